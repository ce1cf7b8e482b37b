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
from pathlib import Path

from mapapi.core.errors import CorruptRepoError, RepoError

SQLITE_HEADER = b"SQLite format 3\x00"
_RESTORE = "restore it from a backup or clone the repository again"


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
    for table, columns in _tables(schema).items():
        have = [row[1] for row in con.execute(f"PRAGMA table_info({table})")]
        if have != columns:
            state = "is missing" if not have else f"has columns {have}, expected {columns}"
            raise CorruptRepoError(f"{path} is damaged: its table {table!r} {state}; {_RESTORE}")


@functools.cache
def _tables(schema: str) -> dict[str, list[str]]:
    """Table name -> column names of the store `schema` creates (built in memory)."""
    con = sqlite3.connect(":memory:")
    try:
        con.executescript(schema)
        names = [r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type = 'table'")]
        return {n: [r[1] for r in con.execute(f"PRAGMA table_info({n})")] for n in names}
    finally:
        con.close()
