"""The query plans of the SQL a store call really runs (for tests of which index it reads)."""

from __future__ import annotations

from collections.abc import Callable

from mapapi.store import SqliteStore


def plans_of(store: SqliteStore, read: Callable[[], object]) -> list[list[str]]:
    """`EXPLAIN QUERY PLAN` of each SELECT from revisions `r` that `read()` runs."""
    statements: list[str] = []
    con = store._con()
    con.set_trace_callback(statements.append)
    try:
        read()
    finally:
        con.set_trace_callback(None)
    reads = [sql for sql in statements if sql.startswith("SELECT") and "revisions r" in sql]
    assert reads, statements
    return [[row[-1] for row in con.execute("EXPLAIN QUERY PLAN " + sql)] for sql in reads]
