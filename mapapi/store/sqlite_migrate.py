"""Bringing a format-1 SQLite store to format 2, once, when it is opened.

Format 2 numbers chunks and commits in the store (`chunks.no`, `commits.no`)
and keys a revision row by its item's 16 bytes, its chunk's and its commit's
numbers (see `sqlite_rows`): a third of the bytes per revision. The tables are
rebuilt in one write transaction, as SQLite's documentation advises for a
change of columns (make the new table, copy, drop the old, rename the new), so
a store is either all format 1 or all format 2, whatever stops the process.
"""

from __future__ import annotations

import logging
import sqlite3
from pathlib import Path

from mapapi.core.errors import CorruptRepoError
from mapapi.store.sqlite_connection import Connections

log = logging.getLogger(__name__)

FROM_VERSION = 1
TO_VERSION = 2

_NEW_TABLES = """
CREATE TABLE chunks_v2 (
    no INTEGER PRIMARY KEY AUTOINCREMENT, id TEXT NOT NULL UNIQUE,
    table_name TEXT NOT NULL REFERENCES tables(name), replication INTEGER NOT NULL DEFAULT 0);
CREATE TABLE commits_v2 (
    no INTEGER PRIMARY KEY AUTOINCREMENT, id TEXT NOT NULL UNIQUE, time INTEGER NOT NULL,
    author TEXT NOT NULL, message TEXT NOT NULL, chunks TEXT NOT NULL,
    author_name TEXT NOT NULL DEFAULT '', view TEXT NOT NULL DEFAULT '');
CREATE TABLE revisions_v2 (
    item_id BLOB NOT NULL, update_time INTEGER NOT NULL, chunk_no INTEGER NOT NULL,
    data BLOB NOT NULL, insert_time INTEGER NOT NULL, removed INTEGER NOT NULL,
    commit_no INTEGER NOT NULL, PRIMARY KEY (item_id, update_time)) WITHOUT ROWID;
"""

_COPY = """
INSERT INTO chunks_v2 (id, table_name, replication)
    SELECT id, table_name, replication FROM chunks ORDER BY id;
INSERT INTO chunks_v2 (id, table_name)
    SELECT DISTINCT chunk_id, table_name FROM revisions
    WHERE chunk_id NOT IN (SELECT id FROM chunks) ORDER BY chunk_id;
INSERT INTO commits_v2 (id, time, author, message, chunks, author_name, view)
    SELECT id, time, author, message, chunks, author_name, view FROM commits ORDER BY time, id;
INSERT INTO revisions_v2
    SELECT mapapi_unhex(r.item_id), r.update_time, c.no, r.data, r.insert_time, r.removed, m.no
    FROM revisions r JOIN chunks_v2 c ON c.id = r.chunk_id JOIN commits_v2 m ON m.id = r.commit_id
    ORDER BY r.item_id, r.update_time;
DROP TABLE revisions;
DROP TABLE commits;
DROP TABLE chunks;
ALTER TABLE chunks_v2 RENAME TO chunks;
ALTER TABLE commits_v2 RENAME TO commits;
ALTER TABLE revisions_v2 RENAME TO revisions;
CREATE INDEX revisions_chunk_time ON revisions (chunk_no, update_time);
CREATE INDEX commits_time ON commits (time);
DROP TABLE IF EXISTS labelled;
DROP TABLE IF EXISTS label_sets;
DELETE FROM meta WHERE key = 'labels';
"""

# A format-1 revision whose commit record is missing, or whose author is not its
# commit's, cannot be written in format 2 (a row keeps its commit's author);
# mapapi never wrote one, so the store is damaged, and nothing is changed.
_UNFIT = """
SELECT COUNT(*) FROM revisions r LEFT JOIN commits m ON m.id = r.commit_id
WHERE m.id IS NULL OR m.author != r.author
"""


def to_format_2(db: Connections, con: sqlite3.Connection, path: Path) -> bool:
    """Rebuild a format-1 store's chunks, commits and revisions in format 2 (and
    drop its label index, derived data made anew on first use); whether it did.

    Raises:
        CorruptRepoError: a revision has no commit record, or another author.
    """
    row = con.execute("SELECT value FROM meta WHERE key = 'version'").fetchone()
    if row is None or row[0] != str(FROM_VERSION):
        return False
    con.create_function("mapapi_unhex", 1, _unhex, deterministic=True)
    # Dropping the old chunks table would cascade to its holders: the keys are
    # checked again once the new one stands (the pragma is a no-op in a transaction).
    con.execute("PRAGMA foreign_keys=OFF")
    try:
        with db.write(con):
            (unfit,) = con.execute(_UNFIT).fetchone()
            if unfit:
                raise CorruptRepoError(
                    f"{path} is damaged: {unfit} revision(s) name a commit it has no record "
                    "of, or another author than their commit's; restore the store from a "
                    "backup or clone the repository again"
                )
            for statement in (_NEW_TABLES + _COPY).split(";"):
                if statement.strip():
                    con.execute(statement)
            con.execute("UPDATE meta SET value = ? WHERE key = 'version'", (str(TO_VERSION),))
    finally:
        con.execute("PRAGMA foreign_keys=ON")
    try:  # the old tables' pages are free now: give them back (a third of the file)
        con.execute("VACUUM")
    except sqlite3.OperationalError as exc:  # another process reads it: SQLite reuses them
        log.info("the store %s keeps its free pages after the upgrade: %s", path, exc)
    return True


def _unhex(text: object) -> bytes:
    """A format-1 item id (32 hex digits) as its 16 bytes; a damaged one is kept as
    it is, for reads to report (`sqlite_rows.revision`)."""
    try:
        return bytes.fromhex(str(text))
    except ValueError:
        return text if isinstance(text, bytes) else str(text).encode()
