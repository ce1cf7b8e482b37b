"""Revisions and commit records as rows of the SQLite store: their columns, reading
a row back (a damaged one raises `CorruptRepoError`), and writing one commit."""

from __future__ import annotations

import sqlite3
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from mapapi._pb.mapapi.v1 import core_pb2
from mapapi.core.errors import CorruptRepoError, UsageError
from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId

COMMIT_COLUMNS = "id, time, author, message, chunks, author_name, view"

# A revision row names its chunk and its commit by their numbers in this store
# (`chunks.no`, `commits.no`) and its item by its 16 bytes; its table and author
# are its chunk's and its commit's. That is 40 bytes less per row than four
# 32-digit ids and a table name, and 16 less per row of the chunk-time index
# (format 2; `sqlite_migrate` brings a format-1 store to it). Reads join the
# two small tables back, by their integer keys.
REV_JOINS = "JOIN chunks c ON c.no = r.chunk_no JOIN commits m ON m.no = r.commit_no"
"""The joins that give revisions `r` the rest of `REV_COLUMNS`."""

REV_FROM = f"revisions r {REV_JOINS}"
"""The FROM clause `REV_COLUMNS` are read from (the revisions as `r`)."""

REV_COLUMNS = (
    "r.item_id, c.table_name, c.id, r.data, r.insert_time, r.update_time, r.removed, m.author, m.id"
)
"""A revision's columns in `REV_FROM`, in the order `revision` reads them."""

CHUNK_NO = "(SELECT no FROM chunks WHERE id = ?)"
"""SQL for the number of the chunk whose id is the parameter."""

COMMIT_NO = "(SELECT no FROM commits WHERE id = ?)"
"""SQL for the number of the commit whose id is the parameter."""


def item_key(item_id: str) -> bytes:
    """An item id as the revisions table keys it (its 16 bytes)."""
    return bytes.fromhex(item_id)


def item_prefix(con: sqlite3.Connection, prefix: str) -> list[str]:
    """The ids of (at most two) items whose id starts with the hex digits `prefix`."""
    if len(prefix) > 32:
        return []
    try:  # the smallest and the largest 16 bytes whose hex starts with it
        lo, hi = (bytes.fromhex(prefix.ljust(32, pad)) for pad in "0f")
    except ValueError:
        return []
    rows = con.execute(
        "SELECT DISTINCT item_id FROM revisions WHERE item_id BETWEEN ? AND ? "
        "ORDER BY item_id LIMIT 2",
        (lo, hi),
    )
    return [bytes(r[0]).hex() for r in rows]


def revision(path: Path, row: sqlite3.Row | tuple) -> Revision:
    """The revision in a row of `REV_COLUMNS` read from the store at `path`."""
    item, table, chunk, data, inserted, updated, removed, author, commit = row
    try:
        return Revision(
            ItemId.from_bytes(item),
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
    item, table, chunk, data, inserted, updated, removed, author, commit = row
    try:
        if not (isinstance(item, bytes) and len(item) == 16):
            raise ValueError("an item id is not 16 bytes")
        if not len(chunk) == len(author) == len(commit) == 32:
            raise ValueError("an id is not 32 hex digits")
        return core_pb2.Revision(
            item_id=item,
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
    """Write a commit's revisions (those here already stay) and advance the clock.

    Raises:
        UsageError: a revision is not the record's (another commit id or author),
            or names a chunk this store does not have.
    """
    numbers = _numbers(con, record, revisions)
    # In primary-key order: random ids inserted as they come touch pages all
    # over the table's B-tree; sorted, a large commit writes in half the time.
    con.executemany(
        "INSERT OR IGNORE INTO revisions (item_id, update_time, chunk_no, data, insert_time, "
        "removed, commit_no) VALUES (?, ?, ?, ?, ?, ?, ?)",
        sorted(
            (
                item_key(r.item_id),
                r.update_time,
                numbers[r.chunk_id],
                r.data,
                r.insert_time,
                int(r.removed),
                numbers[None],
            )
            for r in revisions
        ),
    )
    con.execute(
        "UPDATE meta SET value = MAX(CAST(value AS INTEGER), ?) WHERE key = 'clock'",
        (record.time,),
    )
    con.execute("DELETE FROM meta WHERE key = 'labels'")  # the label index lacks these


def _numbers(
    con: sqlite3.Connection, record: CommitRecord, revisions: Sequence[Revision]
) -> dict[ChunkId | None, int]:
    """The store's numbers of the revisions' chunks, and of the record (key None),
    checking that every revision is the record's: a row keeps its commit's author."""
    numbers: dict[ChunkId | None, int] = {}
    if not revisions:
        return numbers
    row = con.execute("SELECT no, author FROM commits WHERE id = ?", (record.id,)).fetchone()
    if row is None or row[1] != record.author:
        raise UsageError(f"commit {record.id.short} is not recorded here as it is sent")
    numbers[None] = int(row[0])
    for r in revisions:
        if r.commit_id != record.id or r.author != record.author:
            raise UsageError(
                f"a revision of item {r.item_id.short} names commit {r.commit_id.short} by "
                f"{r.author.short}, sent as part of commit {record.id.short} by "
                f"{record.author.short}"
            )
        if r.chunk_id not in numbers:
            found = con.execute("SELECT no FROM chunks WHERE id = ?", (r.chunk_id,)).fetchone()
            if found is None:
                raise UsageError(f"no chunk {r.chunk_id} here for item {r.item_id.short}")
            numbers[r.chunk_id] = int(found[0])
    return numbers


def scope(table: str | None, chunk: ChunkId | None) -> tuple[str, list[object]]:
    """The SQL condition (to append after a WHERE) and its arguments that keep the
    revisions `r` of a table and a chunk (either may be None: any); a table's
    rows are read chunk by chunk (through `revisions_chunk_time`: no index is
    kept by table)."""
    if chunk is not None:
        if table is None:
            return f" AND r.chunk_no = {CHUNK_NO}", [chunk]
        return f" AND r.chunk_no = {CHUNK_NO} AND c.table_name = ?", [chunk, table]
    if table is not None:
        return " AND r.chunk_no IN (SELECT no FROM chunks WHERE table_name = ?)", [table]
    return "", []


def since(time: int, table: str | None, chunk: ChunkId | None) -> tuple[str, list[object]]:
    """The SQL condition (after a WHERE) and its arguments that keep the revisions
    `r` written after `time` to `chunk` (of `table`, if given), or else to the
    chunks of `table`, each read through the (chunk, time) index; with neither,
    every revision is read."""
    if chunk is not None:
        where = f"r.chunk_no = {CHUNK_NO} AND r.update_time > ?"
        if table is None:
            return where, [chunk, time]
        return where + " AND c.table_name = ?", [chunk, time, table]
    if table is not None:
        return (
            "r.chunk_no IN (SELECT no FROM chunks WHERE table_name = ?) AND r.update_time > ?",
            [table, time],
        )
    return "r.update_time > ?", [time]


def of_commit(
    con: sqlite3.Connection,
    commit_id: CommitId,
    parts: Iterable[tuple[ChunkId, int]],
    columns: str = REV_COLUMNS,
) -> list[tuple[Any, ...]]:
    """`columns` (of `REV_FROM`) of the revisions commit `commit_id` wrote to each
    (chunk, time) of `parts` (a commit's revisions in a chunk all have its time),
    read through the (chunk, time) index: the store keeps no index by commit."""
    sql = (
        f"SELECT {columns} FROM {REV_FROM} WHERE r.chunk_no = {CHUNK_NO} "
        f"AND r.update_time = ? AND r.commit_no = {COMMIT_NO}"
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
