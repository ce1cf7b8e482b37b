"""Is a file a mapapi store this version can use? Checked when a store opens (DESIGN §11).

A repository's store may be damaged (a truncated copy, a bad disk), foreign
(another application's SQLite file, or no SQLite file at all), written by a
newer mapapi, or unreadable (its permissions). Each case raises one error that
names the file and says what to do, before anything reads map data from it;
`mapctl` prints it as one line (exit 1), never a traceback.
"""

from __future__ import annotations

import functools
import os
import sqlite3
import sys
from collections.abc import Callable
from pathlib import Path

from mapapi.core.errors import CorruptPayload, CorruptRepoError, MapError, NoSpaceLeft, RepoError
from mapapi.core.history import Revision

SQLITE_HEADER = b"SQLite format 3\x00"
_RESTORE = "restore it from a backup or clone the repository again"

NEARLY_FULL = 1024 * 1024
"""Free bytes below which a SQLite I/O error is read as a full disk: SQLite
reports a write it could not make as SQLITE_FULL, but a shared-memory index
(`-shm`) or a journal it could not grow as SQLITE_IOERR."""


def check_file(path: Path) -> None:
    """Refuse a store file that cannot be read or is no SQLite database.

    Raises:
        RepoError: it cannot be read, or it or its folder cannot be written
            (permissions, a folder in its place).
        CorruptRepoError: it is empty or does not start like a SQLite file.
    """
    try:
        with path.open("rb") as f:
            head = f.read(len(SQLITE_HEADER))
    except OSError as exc:
        raise RepoError(
            f"cannot read {path}: {exc.strerror or exc}; check its owner and permissions "
            "(`ls -l`), or run mapctl as the user that owns the repository"
        ) from exc
    if not (os.access(path, os.W_OK) and os.access(path.parent, os.W_OK)):
        # SQLite's write-ahead log needs both, even to read.
        raise RepoError(
            f"cannot write {path} or its folder: permission denied; check their owner and "
            "permissions (`ls -l`), or run mapctl as the user that owns the repository"
        )
    if not head:
        raise CorruptRepoError(f"{path} is not a mapapi store: the file is empty; {_RESTORE}")
    if head != SQLITE_HEADER:
        raise CorruptRepoError(
            f"{path} is not a mapapi store: not even a SQLite database (it starts {head!r}); "
            f"{_RESTORE}"
        )


def storage_error(path: Path, exc: sqlite3.Error) -> MapError | None:
    """The honest error for a SQLite failure of the store at `path` that is no
    damage of it: a full disk, or the disk failing to read or write; None for
    anything else (the caller's error stands).

    A full disk used to read as "not a mapapi store ... restore it from a backup",
    advice that loses data: SQLite refuses a write it cannot make whole, so the
    store is intact and only the failed command's change is not in it.
    """
    primary = getattr(exc, "sqlite_errorcode", -1) & 0xFF
    folder = path.parent
    if primary == sqlite3.SQLITE_FULL or (
        primary == sqlite3.SQLITE_IOERR and _free_bytes(folder) < NEARLY_FULL
    ):
        return NoSpaceLeft(
            f"no space left on the disk of {folder} ({_free_bytes(folder)} bytes free; "
            f"SQLite: {exc}): the store is intact (the write that failed was undone whole); "
            "free some space, then run it again"
        )
    if primary == sqlite3.SQLITE_IOERR:
        return RepoError(
            f"cannot read or write {path}: {exc} ({getattr(exc, 'sqlite_errorname', '')}), "
            "a failure of the disk or its file system rather than of the store; check the "
            "disk (`dmesg`, `df`), then run the command again"
        )
    return None


def _free_bytes(folder: Path) -> int:
    """Bytes this user may still write on the file system of `folder` (unknown: a lot)."""
    try:
        stat = os.statvfs(folder)
    except OSError:
        return sys.maxsize
    return stat.f_bavail * stat.f_frsize


def check_schema(con: sqlite3.Connection, path: Path, schema: str, fmt: str, version: int) -> None:
    """Refuse a SQLite file that is not a mapapi store of a version this code reads,
    or whose tables are missing or changed.

    Args:
        schema: the store's CREATE statements (the tables and their columns).
        fmt: the value of the store's format marker in its `meta` table.
        version: the newest store format version this code reads.

    Raises:
        CorruptRepoError: naming the file and what to do.
    """
    names = {row[0] for row in con.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
    marker = None
    if "meta" in names:
        marker = con.execute("SELECT value FROM meta WHERE key = 'format'").fetchone()
    if marker is None or marker[0] != fmt:
        raise CorruptRepoError(
            f"{path} is not a mapapi store: a SQLite database of another application (no "
            f"mapapi format marker; tables: {', '.join(sorted(names)) or 'none'}); {_RESTORE}"
        )
    row = con.execute("SELECT value FROM meta WHERE key = 'version'").fetchone()
    found = int(row[0]) if row is not None and str(row[0]).isdigit() else None
    if found is None or found > version:
        what = f"store format {found}" if found is not None else "an unknown store format"
        raise CorruptRepoError(
            f"{path} was written in {what}; this mapapi reads formats up to {version}: "
            "upgrade mapapi (`pip install -U mapapi`), or clone the repository again"
        )
    for table, columns in schema_tables(schema).items():
        have = [row[1] for row in con.execute(f"PRAGMA table_info({table})")]
        if have != columns:
            state = "is missing" if not have else f"has columns {have}, expected {columns}"
            raise CorruptRepoError(f"{path} is damaged: its table {table!r} {state}; {_RESTORE}")


@functools.cache
def schema_tables(schema: str) -> dict[str, list[str]]:
    """Table name -> column names of the store `schema` creates (built in memory)."""
    con = sqlite3.connect(":memory:")
    try:
        con.executescript(schema)
        names = [r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type = 'table'")]
        return {n: [r[1] for r in con.execute(f"PRAGMA table_info({n})")] for n in names}
    finally:
        con.close()


def locate_payload(exc: CorruptPayload, store: object) -> CorruptPayload | None:
    """`exc` naming the store's file and the items whose revisions hold its bytes
    (a scan of the table's revisions: only ever on this error's path), or None
    when it names them already.

    Args:
        store: the `Store` the payload was read from (a file store has a `path`).
    """
    if exc.where:
        return None
    chunks = getattr(store, "chunks", None)
    revisions: Callable[[object], list[Revision]] | None = getattr(store, "chunk_revisions", None)
    items: set[str] = set()
    if chunks is not None and revisions is not None:
        for chunk in chunks(exc.table):
            items.update(str(r.item_id) for r in revisions(chunk.id) if r.data == exc.data)
    return exc.at(getattr(store, "path", "the store"), sorted(items))


def store_bytes(path: Path) -> int:
    """The store's size on disk: the SQLite file at `path` and its write-ahead log."""
    return sum(p.stat().st_size for p in (path, path.with_name(path.name + "-wal")) if p.exists())
