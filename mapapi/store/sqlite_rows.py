"""Revisions and commit records as rows of the SQLite store: their columns, reading
a row back (a damaged one raises `CorruptRepoError`), and writing one commit."""

from __future__ import annotations

import sqlite3
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from mapapi._pb.mapapi.v1 import core_pb2
from mapapi.core.errors import CorruptRepoError
from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId

COMMIT_COLUMNS = "id, time, author, message, chunks, author_name, view"

REV_COLUMNS = (
    "item_id, table_name, chunk_id, data, insert_time, update_time, removed, author, commit_id"
)


def revision(path: Path, row: sqlite3.Row | tuple) -> Revision:
    """The revision in a row of `REV_COLUMNS` read from the store at `path`."""
    item_id, table, chunk, data, inserted, updated, removed, author, commit = row
    try:
        return Revision(
            ItemId(item_id),
            table,
            ChunkId(chunk),
            bytes(data),
            inserted,
            updated,
            bool(removed),
            PeerId(author),
            CommitId(commit),
        )
    except (TypeError, ValueError) as exc:
        raise _damaged_row(path, "revision", exc) from exc


def revision_pb(path: Path, row: tuple) -> core_pb2.Revision:
    """The revision in a row of `REV_COLUMNS` as its wire message (`revision`, then
    `codec.revision_to_pb`, in one step; a damaged row raises `CorruptRepoError`)."""
    item_id, table, chunk, data, inserted, updated, removed, author, commit = row
    try:
        if not len(item_id) == len(chunk) == len(author) == len(commit) == 32:
            raise ValueError("an id is not 32 hex digits")
        return core_pb2.Revision(
            item_id=bytes.fromhex(item_id),
            table=table,
            chunk_id=bytes.fromhex(chunk),
            data=data,
            insert_time=inserted,
            update_time=updated,
            removed=bool(removed),
            author=bytes.fromhex(author),
            commit_id=bytes.fromhex(commit),
        )
    except (TypeError, ValueError) as exc:
        raise _damaged_row(path, "revision", exc) from exc


def record(path: Path, row: tuple) -> CommitRecord:
    """The commit record in a row of `COMMIT_COLUMNS` read from the store at `path`."""
    cid, time, author, message, chunks, author_name, view = row
    try:
        return CommitRecord(
            CommitId(cid),
            time,
            PeerId(author),
            message,
            tuple(ChunkId(c) for c in chunks.split(",") if c),
            author_name,
            view,
        )
    except (AttributeError, TypeError, ValueError) as exc:
        raise _damaged_row(path, "commit record", exc) from exc


def _damaged_row(path: Path, what: str, exc: Exception) -> CorruptRepoError:
    return CorruptRepoError(
        f"a {what} in {path} is damaged: {exc}; restore the store from a backup "
        "or clone the repository again"
    )


def write_commit(
    con: sqlite3.Connection, record: CommitRecord, revisions: Sequence[Revision]
) -> bool:
    """Write the record and its revisions (inside the caller's write transaction);
    whether the record is new here (`write_record`)."""
    new = write_record(con, record)
    write_revisions(con, record, revisions)
    return new


def write_record(con: sqlite3.Connection, record: CommitRecord) -> bool:
    """Write a commit's record unless it is here; whether it was not (then the
    store's count of the commit records it wrote, `meta` "applied", grows by one:
    see `store/mark.py`). A record is written with the commit's first revisions,
    so when it is new, none of its revisions is here yet."""
    # Idempotent and additive: a commit that spans chunks reaches a holder
    # as one batch per chunk, each applied on its own.
    new = (
        con.execute(
            f"INSERT OR IGNORE INTO commits ({COMMIT_COLUMNS}) VALUES (?, ?, ?, ?, ?, ?, ?)",
            (
                record.id,
                record.time,
                record.author,
                record.message,
                ",".join(record.chunks),
                record.author_name,
                record.view,
            ),
        ).rowcount
        == 1
    )
    if new:
        con.execute("UPDATE meta SET value = CAST(value AS INTEGER) + 1 WHERE key = 'applied'")
    return new


def write_revisions(
    con: sqlite3.Connection, record: CommitRecord, revisions: Sequence[Revision]
) -> None:
    """Write a commit's revisions (those here already stay) and advance the clock."""
    # In primary-key order: random ids inserted as they come touch pages all
    # over the table's B-tree; sorted, a large commit writes in half the time.
    con.executemany(
        "INSERT OR IGNORE INTO revisions (item_id, update_time, table_name, chunk_id, "
        "data, insert_time, removed, author, commit_id) "
        "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
        sorted(
            (
                r.item_id,
                r.update_time,
                r.table,
                r.chunk_id,
                r.data,
                r.insert_time,
                int(r.removed),
                r.author,
                r.commit_id,
            )
            for r in revisions
        ),
    )
    con.execute(
        "UPDATE meta SET value = MAX(CAST(value AS INTEGER), ?) WHERE key = 'clock'",
        (record.time,),
    )
    con.execute("DELETE FROM meta WHERE key = 'labels'")  # the label index lacks these


def scope(table: str | None, chunk: ChunkId | None) -> tuple[str, list[object]]:
    """The SQL condition (to append after a WHERE) and its arguments that keep the
    revisions `r` of a table and a chunk (either may be None: any); a table's
    rows are read chunk by chunk (through `revisions_chunk_time`: no index is
    kept by table)."""
    if chunk is not None:
        if table is None:
            return " AND r.chunk_id = ?", [chunk]
        return " AND r.chunk_id = ? AND r.table_name = ?", [chunk, table]
    if table is not None:
        return " AND r.chunk_id IN (SELECT id FROM chunks WHERE table_name = ?)", [table]
    return "", []


def since(time: int, table: str | None, chunk: ChunkId | None) -> tuple[str, list[object]]:
    """The SQL condition (after a WHERE) and its arguments that keep the revisions
    `r` written after `time` to `chunk` (of `table`, if given), or else to the
    chunks of `table`, each read through the (chunk, time) index; with neither,
    every revision is read."""
    if chunk is not None:
        if table is None:
            return "r.chunk_id = ? AND r.update_time > ?", [chunk, time]
        return "r.chunk_id = ? AND r.update_time > ? AND r.table_name = ?", [chunk, time, table]
    if table is not None:
        return (
            "r.chunk_id IN (SELECT id FROM chunks WHERE table_name = ?) AND r.update_time > ?",
            [table, time],
        )
    return "r.update_time > ?", [time]


def of_commit(
    con: sqlite3.Connection,
    commit_id: CommitId,
    parts: Iterable[tuple[ChunkId, int]],
    columns: str = REV_COLUMNS,
) -> list[tuple[Any, ...]]:
    """`columns` of the revisions commit `commit_id` wrote to each (chunk, time) of
    `parts` (a commit's revisions in a chunk all have its time), read through the
    (chunk, time) index: the store keeps no index by commit."""
    sql = (
        f"SELECT {columns} FROM revisions WHERE chunk_id = ? AND update_time = ? AND commit_id = ?"
    )
    return [row for chunk, time in parts for row in con.execute(sql, (chunk, time, commit_id))]


def commit_record(path: Path, con: sqlite3.Connection, commit_id: CommitId) -> CommitRecord | None:
    """The record of a commit (None: unknown here), from the store at `path`."""
    row = con.execute(f"SELECT {COMMIT_COLUMNS} FROM commits WHERE id = ?", (commit_id,)).fetchone()
    return None if row is None else record(path, row)


def of_record(
    con: sqlite3.Connection, commit: CommitRecord, columns: str = REV_COLUMNS
) -> list[tuple[Any, ...]]:
    """`of_commit` for every chunk the commit names, at its time."""
    return of_commit(con, commit.id, [(c, commit.time) for c in commit.chunks], columns)
