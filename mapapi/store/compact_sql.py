"""Dropping old history from the SQLite store (`mapctl gc`, issue 14 §4).

A revision goes when it can no longer be read at or after the horizon: a newer
revision of its item was written at or before the horizon. So every read at the
horizon or later reads what it read before, and the newest revision of each item
always stays (a tombstone too). With `keep`, each item's `keep` newest revisions
stay as well. The caller picks a horizon no open view or transaction began before.

A chunk that loses revisions gets a compacted part of its hash chain
(`chain_sql.compacted`): its links up to the newest commit that lost one. Those
links stand as they are (the history can no longer rebuild them); the commits
after them lost nothing (the part ends at the newest commit that did), so
`fsck`, the check before a snapshot goes out and a new holder's rebuild go on
from the last compacted link. Commit records stay, so `log` still
says who changed what, when.

Functions take a connection and expect the caller's write transaction.
"""

from __future__ import annotations

import sqlite3
from dataclasses import dataclass

from mapapi.store import chain_sql, sqlite_rows

FLOOR = "gc_horizon"
"""The `meta` key of `floor`."""


@dataclass(frozen=True)
class Compaction:
    """What one `compact` dropped."""

    horizon: int
    keep: int | None
    revisions: int  # dropped
    bytes: int  # of their payloads
    items: int  # whose history they were
    chunks: int  # whose chains gained a compacted part


_DOOMED = f"""
INSERT INTO gc_doomed
SELECT r.item_id, r.update_time, c.id, m.id, LENGTH(r.data) FROM {sqlite_rows.REV_FROM}
WHERE r.update_time < :horizon
  AND r.update_time < (SELECT MAX(x.update_time) FROM revisions x
                       WHERE x.item_id = r.item_id AND x.update_time <= :horizon)
  AND (:keep IS NULL OR (SELECT COUNT(*) FROM revisions z
                         WHERE z.item_id = r.item_id AND z.update_time > r.update_time) >= :keep)
"""


def compact(con: sqlite3.Connection, horizon: int, keep: int | None = None) -> Compaction:
    """Drop the revisions no read at or after `horizon` sees (beyond each item's
    `keep` newest), with their label-index rows, and extend the touched chunks'
    compacted chain parts."""
    con.execute(
        "CREATE TEMP TABLE IF NOT EXISTS gc_doomed (item_id BLOB, update_time INTEGER, "
        "chunk_id TEXT, commit_id TEXT, size INTEGER, PRIMARY KEY (item_id, update_time)) "
        "WITHOUT ROWID"
    )
    con.execute("DELETE FROM gc_doomed")
    con.execute(_DOOMED, {"horizon": horizon, "keep": keep})
    revisions, size, items = con.execute(
        "SELECT COUNT(*), COALESCE(SUM(size), 0), COUNT(DISTINCT item_id) FROM gc_doomed"
    ).fetchone()
    bases = con.execute(
        "SELECT d.chunk_id, MAX(c.seq) FROM gc_doomed d JOIN raft_chain c "
        "ON c.chunk_id = d.chunk_id AND c.commit_id = d.commit_id GROUP BY d.chunk_id"
    ).fetchall()
    for chunk, seq in bases:
        chain_sql.set_compacted(con, chunk, max(seq, chain_sql.compacted(con, chunk)))
    if _has_table(con, "labelled"):
        con.execute(
            "DELETE FROM labelled WHERE (item_id, update_time) IN "
            "(SELECT item_id, update_time FROM gc_doomed)"
        )
    con.execute(
        "DELETE FROM revisions WHERE (item_id, update_time) IN "
        "(SELECT item_id, update_time FROM gc_doomed)"
    )
    con.execute("DELETE FROM gc_doomed")
    if revisions:
        con.execute(
            "INSERT INTO meta VALUES (?, ?) ON CONFLICT (key) DO UPDATE "
            "SET value = MAX(CAST(value AS INTEGER), excluded.value)",
            (FLOOR, horizon),
        )
    return Compaction(horizon, keep, revisions, size, items, len(bases))


def floor(con: sqlite3.Connection) -> int:
    """The newest horizon a `compact` dropped revisions below: a read at an
    earlier time may miss them (0: history is whole)."""
    row = con.execute("SELECT value FROM meta WHERE key = ?", (FLOOR,)).fetchone()
    return 0 if row is None else int(row[0])


def _has_table(con: sqlite3.Connection, name: str) -> bool:
    found = con.execute("SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = ?", (name,))
    return found.fetchone() is not None
