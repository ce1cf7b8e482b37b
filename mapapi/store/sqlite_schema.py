"""The SQLite store's schema: creating a new store, and bringing an older one up to date.

Only an empty database becomes a new store, and only a file marked as a mapapi
store is upgraded; `check_schema` then refuses anything else unchanged.
"""

from __future__ import annotations

import sqlite3

from mapapi.store import chain_sql, raft_sql, sqlite_migrate
from mapapi.store.file_check import check_schema
from mapapi.store.mark import APPLIED
from mapapi.store.sqlite_connection import Connections

FORMAT = "mapapi-store"
SCHEMA_VERSION = sqlite_migrate.TO_VERSION

# Format 2 (see `sqlite_rows` and `sqlite_migrate`). Only the indexes reads use:
# a chunk's rows, what it got since a time, and a commit's rows (its chunks at
# its time) are all read through (chunk, time); a table's rows are its chunks'.
# Each index more cost 7-13 % of the store and a random-order B-tree insert per
# revision, and a time index over the whole table made the mission rules' "what
# did chunk C get since T" read every revision since T of every chunk.
_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS tables (
    name TEXT PRIMARY KEY, type_name TEXT NOT NULL, replication INTEGER NOT NULL DEFAULT 0);
CREATE TABLE IF NOT EXISTS chunks (
    no INTEGER PRIMARY KEY AUTOINCREMENT, id TEXT NOT NULL UNIQUE,
    table_name TEXT NOT NULL REFERENCES tables(name), replication INTEGER NOT NULL DEFAULT 0);
CREATE TABLE IF NOT EXISTS revisions (
    item_id BLOB NOT NULL, update_time INTEGER NOT NULL, chunk_no INTEGER NOT NULL,
    data BLOB NOT NULL, insert_time INTEGER NOT NULL, removed INTEGER NOT NULL,
    commit_no INTEGER NOT NULL, PRIMARY KEY (item_id, update_time)) WITHOUT ROWID;
CREATE INDEX IF NOT EXISTS revisions_chunk_time ON revisions (chunk_no, update_time);
CREATE TABLE IF NOT EXISTS commits (
    no INTEGER PRIMARY KEY AUTOINCREMENT, id TEXT NOT NULL UNIQUE, time INTEGER NOT NULL,
    author TEXT NOT NULL, message TEXT NOT NULL, chunks TEXT NOT NULL,
    author_name TEXT NOT NULL DEFAULT '', view TEXT NOT NULL DEFAULT '');
CREATE INDEX IF NOT EXISTS commits_time ON commits (time);
CREATE TABLE IF NOT EXISTS views (name TEXT PRIMARY KEY, body BLOB NOT NULL);
CREATE TABLE IF NOT EXISTS holders (
    chunk_id TEXT NOT NULL REFERENCES chunks(id) ON DELETE CASCADE, peer_id TEXT NOT NULL,
    PRIMARY KEY (chunk_id, peer_id)) WITHOUT ROWID;
"""

# Columns added to format 1, with how to add them to an older store (its
# records then name no author and no view: `log` falls back to other names).
_ADDED_COLUMNS = {
    "tables": (("replication", "INTEGER NOT NULL DEFAULT 0"),),  # 0: the swarm's default
    "chunks": (("replication", "INTEGER NOT NULL DEFAULT 0"),),  # 0: its table's
    "commits": (
        ("author_name", "TEXT NOT NULL DEFAULT ''"),
        ("view", "TEXT NOT NULL DEFAULT ''"),
    ),
}


def setup(db: Connections, create: bool) -> None:
    """Create the store's tables (with `create`, in an empty database), upgrade an
    older store, and check the schema.

    Raises:
        CorruptRepoError: not a mapapi store, of a newer format, or lacking a table.
    """
    con = db.con()
    if create and con.execute("SELECT 1 FROM sqlite_master").fetchone() is None:
        # Only an empty database becomes a new store: never add our tables to
        # another application's database (it fails the marker check below).
        con.execute("PRAGMA journal_mode=WAL")
        with db.write(con):
            for statement in _SCHEMA.split(";"):
                if statement.strip():
                    con.execute(statement)
            con.execute(
                "INSERT OR IGNORE INTO meta VALUES ('format', ?), ('version', ?), ('clock', '0'), "
                "(?, '0'), (?, '1')",
                (FORMAT, str(SCHEMA_VERSION), APPLIED, chain_sql.LINKED),
            )
    _add_columns(db, con)
    if {"chunks", "commits", "revisions"} <= (_tables_if_ours(con) or set()):
        sqlite_migrate.to_format_2(db, con, db.path)  # else check_schema refuses it
    _add_tables(db, con, raft_sql.RAFT_SCHEMA, raft_sql.RAFT_TABLES)
    _add_tables(db, con, chain_sql.CHAIN_SCHEMA, chain_sql.CHAIN_TABLES)
    _link_commits(db, con)
    schema = _SCHEMA + raft_sql.RAFT_SCHEMA + chain_sql.CHAIN_SCHEMA
    check_schema(con, db.path, schema, FORMAT, SCHEMA_VERSION)


def _link_commits(db: Connections, con: sqlite3.Connection) -> None:
    """Bring a store written before every commit was linked and counted up to date,
    once: its count of commit records (`store/mark.py`) starts at the records it
    holds, and every chunk gets its hash chain (`chain_sql.link_all`)."""
    tables = _tables_if_ours(con)
    if tables is None or not {"commits", "chunks", "revisions", "raft_chain"} <= tables:
        return  # check_schema refuses it
    wanted = (APPLIED, chain_sql.LINKED)
    keys = {r[0] for r in con.execute("SELECT key FROM meta WHERE key IN (?, ?)", wanted)}
    if keys == set(wanted):
        return
    with db.write(con):
        con.execute("INSERT OR IGNORE INTO meta SELECT ?, COUNT(*) FROM commits", (APPLIED,))
        chain_sql.link_all(con, db.path)


def _add_tables(
    db: Connections, con: sqlite3.Connection, schema: str, names: tuple[str, ...]
) -> None:
    """Give a mapapi store the tables of `schema` (`names`) it lacks (no write
    transaction when it has them)."""
    tables = _tables_if_ours(con)
    if tables is None or tables.issuperset(names):
        return
    with db.write(con):
        for statement in schema.split(";"):
            if statement.strip():
                con.execute(statement)


def _add_columns(db: Connections, con: sqlite3.Connection) -> None:
    """Bring a store written before `_ADDED_COLUMNS` up to date (idempotent).

    Only a file marked as a mapapi store is touched; `check_schema` then
    refuses anything else unchanged."""
    if _tables_if_ours(con) is None:
        return
    for table, columns in _ADDED_COLUMNS.items():
        have = {row[1] for row in con.execute(f"PRAGMA table_info({table})")}
        missing = [(n, t) for n, t in columns if have and n not in have]
        if missing:
            with db.write(con):
                for name, definition in missing:
                    con.execute(f"ALTER TABLE {table} ADD COLUMN {name} {definition}")


def _tables_if_ours(con: sqlite3.Connection) -> set[str] | None:
    """The database's tables if it is marked as a mapapi store, else None."""
    tables = {r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type='table'")}
    if "meta" not in tables:
        return None
    marker = con.execute("SELECT value FROM meta WHERE key = 'format'").fetchone()
    return tables if marker is not None and marker[0] == FORMAT else None
