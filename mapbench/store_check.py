"""Is a peer's SQLite store intact? The checks `mapctl bench fuzz` runs after a fuzz run.

`problems` reads the file (read-only, beside a running peer: WAL lets it) and
checks SQLite's own integrity and foreign keys plus the store's invariants:
every revision belongs to a known chunk of its own table and to a recorded
commit, and an item lives in one chunk only. `unexplained` compares two
snapshots and lists what changed outside the chunks allowed to change.
"""

from __future__ import annotations

import sqlite3
from collections.abc import Collection, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

DATA_TABLES = ("tables", "chunks", "holders", "revisions", "commits")
"""The store's tables that hold map data (views are the CLI's scratch state)."""

Snapshot = dict[str, list[tuple[Any, ...]]]

_INVARIANTS = {
    "revisions of a chunk this store does not know": """
        SELECT count(*) FROM revisions r LEFT JOIN chunks c ON c.no = r.chunk_no
        WHERE c.no IS NULL""",
    "revisions of a commit with no record": """
        SELECT count(*) FROM revisions r LEFT JOIN commits m ON m.no = r.commit_no
        WHERE m.no IS NULL""",
    "items that live in more than one chunk": """
        SELECT count(*) FROM (SELECT item_id FROM revisions GROUP BY item_id
                              HAVING count(DISTINCT chunk_no) > 1)""",
    "revisions written at another time than their commit's": """
        SELECT count(*) FROM revisions r JOIN commits m ON m.no = r.commit_no
        WHERE m.time != r.update_time""",
}


@contextmanager
def read_only(path: Path) -> Iterator[sqlite3.Connection]:
    """A read-only connection to the store at `path` (closed on exit)."""
    con = sqlite3.connect(f"file:{path}?mode=ro", uri=True, timeout=30)
    try:
        yield con
    finally:
        con.close()


# Revisions with their chunk's and commit's ids, not the store's numbers for them.
_SELECT = {
    "revisions": "SELECT r.item_id, r.update_time, c.id, r.data, r.insert_time, r.removed, m.id "
    "FROM revisions r LEFT JOIN chunks c ON c.no = r.chunk_no "
    "LEFT JOIN commits m ON m.no = r.commit_no"
}


def snapshot(path: Path) -> Snapshot:
    """Every row of the store's tables that hold map data, sorted."""
    with read_only(path) as con:
        return {t: sorted(con.execute(_SELECT.get(t, f"SELECT * FROM {t}"))) for t in DATA_TABLES}


def problems(path: Path) -> list[str]:
    """What is wrong with the store at `path` (empty when it is intact)."""
    with read_only(path) as con:
        found = []
        integrity = [row[0] for row in con.execute("PRAGMA integrity_check")]
        if integrity != ["ok"]:
            found.append(f"PRAGMA integrity_check: {'; '.join(integrity[:5])}")
        dangling = con.execute("PRAGMA foreign_key_check").fetchall()
        if dangling:
            found.append(f"PRAGMA foreign_key_check: {len(dangling)} dangling row(s)")
        for what, query in _INVARIANTS.items():
            (n,) = con.execute(query).fetchone()
            if n:
                found.append(f"{n} {what}")
        return found


def unexplained(
    before: Snapshot,
    after: Snapshot,
    may_change: Collection[str],
    regrouped: Collection[str] = (),
) -> list[str]:
    """What changed between two snapshots outside the chunks in `may_change`
    (and, for their holders only, those in `regrouped`).

    Tables and chunks must be equal; holders and revisions of the other chunks
    equal; old commit records unchanged; new records only if a chunk may change.
    """
    found = []
    for table in ("tables", "chunks"):
        if before[table] != after[table]:
            found.append(f"the {table} table changed")
    # holders (chunk_id, peer_id); revisions (item_id, update_time, chunk_id, ...)
    for table, column in (("holders", 0), ("revisions", 2)):
        free = set(may_change) | (set(regrouped) if table == "holders" else set())
        old = [r for r in before[table] if r[column] not in free]
        new = [r for r in after[table] if r[column] not in free]
        if old != new:
            found.append(f"{table} of chunks that may not change differ ({len(old)} -> {len(new)})")
    old_commits, new_commits = set(before["commits"]), set(after["commits"])
    if not old_commits <= new_commits:
        found.append(f"{len(old_commits - new_commits)} commit record(s) changed or vanished")
    if new_commits - old_commits and not may_change:
        # A record comes with a commit applied from a chunk's log.
        found.append(f"{len(new_commits - old_commits)} new commit record(s)")
    return found
