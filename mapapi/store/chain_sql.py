"""Each chunk's hash chain in the SQLite store (issue 18 §3, `core/chain.py`), and
what the holders' comparisons of their chains found.

The links live in the `raft_chain` table (`raft_sql`: named when only a chunk's
log linked commits; every commit path links them now): one row per commit of the
chunk, numbered from 1, the last one the chunk's head. `extend` adds a commit's
links as `SqliteStore.apply_commit` writes it; `rebuild` makes a chunk's chain
anew from its stored history, for a replica taken in from a holder and for a
store written before commits were linked (once, when it is opened).

Functions take a connection; those that write expect the caller's write
transaction (`SqliteStore` opens it).
"""

from __future__ import annotations

import sqlite3
import time
from collections.abc import Sequence
from pathlib import Path

from mapapi.core import chain
from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, CommitId, PeerId
from mapapi.store import raft_sql, sqlite_replica, sqlite_rows
from mapapi.store.base import Divergence

CHAIN_SCHEMA = """
CREATE TABLE IF NOT EXISTS chain_diverged (
    chunk_id TEXT NOT NULL, peer_id TEXT NOT NULL, position INTEGER NOT NULL,
    detail TEXT NOT NULL, noticed REAL NOT NULL,
    PRIMARY KEY (chunk_id, peer_id)) WITHOUT ROWID;
CREATE TABLE IF NOT EXISTS chain_compacted (
    chunk_id TEXT PRIMARY KEY, seq INTEGER NOT NULL) WITHOUT ROWID;
"""
CHAIN_TABLES = ("chain_diverged", "chain_compacted")
"""The tables above; an older store gains the ones it lacks."""

LINKED = "chains"
"""The `meta` key saying every chunk's chain links all its commits (`link_all`)."""


def head_commit(con: sqlite3.Connection, chunk: str) -> str | None:
    """The commit the chunk's newest link stands for, or None before its first."""
    row = con.execute(
        "SELECT commit_id FROM raft_chain WHERE chunk_id = ? ORDER BY seq DESC LIMIT 1", (chunk,)
    ).fetchone()
    return None if row is None else str(row[0])


def add_link(con: sqlite3.Connection, chunk: str, commit_id: str, link: bytes) -> None:
    """Append a commit's link unless the chunk's head links that commit already."""
    if head_commit(con, chunk) != commit_id:
        raft_sql.add_link(con, chunk, commit_id, link)


def unwritten(
    con: sqlite3.Connection, record: CommitRecord, revisions: Sequence[Revision]
) -> set[ChunkId]:
    """The chunks of `revisions` that hold none of `record`'s revisions yet (their
    part of the commit is new here, so their chains get its link)."""
    parts = {(r.chunk_id, r.update_time) for r in revisions}
    return {
        chunk
        for chunk, time in parts
        if not sqlite_rows.of_commit(con, record.id, [(chunk, time)], columns="1")
    }


def extend(
    con: sqlite3.Connection,
    record: CommitRecord,
    revisions: Sequence[Revision],
    chunks: set[ChunkId],
) -> None:
    """Link `record` into the chain of each chunk in `chunks` it wrote."""
    for chunk, link in chain.extend(lambda c: raft_sql.head(con, c), record, revisions, chunks):
        raft_sql.add_link(con, chunk, record.id, link)


def rebuild(con: sqlite3.Connection, path: Path, chunk: ChunkId) -> None:
    """Make the chunk's chain anew from its stored history (`chain.rebuild`), after
    its compacted part."""
    records = {c.id: c for c in sqlite_replica.chunk_commits(path, con, chunk)}
    revisions = sqlite_replica.chunk_revisions(path, con, chunk)
    kept = base(con, chunk)
    replace(con, chunk, chain.rebuild(chunk, records, revisions, kept), len(kept))


def replace(
    con: sqlite3.Connection,
    chunk: ChunkId,
    links: list[tuple[CommitId, bytes]],
    compacted: int = 0,
) -> None:
    """Make `links` the chunk's whole chain (rebuilt by the caller, say before a
    write transaction, from the history it installs), its first `compacted`
    links those of commits whose history is gone in part (`compacted`)."""
    con.execute("DELETE FROM raft_chain WHERE chunk_id = ?", (chunk,))
    con.executemany(
        "INSERT INTO raft_chain (chunk_id, seq, commit_id, link) VALUES (?, ?, ?, ?)",
        [(chunk, seq, commit, link) for seq, (commit, link) in enumerate(links, 1)],
    )
    set_compacted(con, chunk, compacted)


def compacted(con: sqlite3.Connection, chunk: str) -> int:
    """How many of the chunk's first links stand for commits some of whose
    revisions `mapctl gc` dropped (0: its history is whole)."""
    row = con.execute("SELECT seq FROM chain_compacted WHERE chunk_id = ?", (chunk,)).fetchone()
    return 0 if row is None else int(row[0])


def set_compacted(con: sqlite3.Connection, chunk: str, seq: int) -> None:
    """Record that the chunk's first `seq` links are its compacted part."""
    if seq:
        con.execute("INSERT OR REPLACE INTO chain_compacted VALUES (?, ?)", (chunk, seq))
    else:
        con.execute("DELETE FROM chain_compacted WHERE chunk_id = ?", (chunk,))


def base(con: sqlite3.Connection, chunk: str) -> list[tuple[CommitId, bytes]]:
    """The chunk's compacted links, oldest first (empty: its history is whole)."""
    rows = con.execute(
        "SELECT commit_id, link FROM raft_chain WHERE chunk_id = ? AND seq <= ? ORDER BY seq",
        (chunk, compacted(con, chunk)),
    )
    return [(CommitId(c), bytes(link)) for c, link in rows]


def link_all(con: sqlite3.Connection, path: Path) -> None:
    """Give every chunk with commits and no chain its chain, once per store: a store
    written before every commit path linked its commits (see docs/guarantees.md,
    "Verifiable history"). Each holder rebuilds from the same history in the
    same order, so holders of one history agree, and differing ones are found."""
    if con.execute("SELECT 1 FROM meta WHERE key = ?", (LINKED,)).fetchone() is not None:
        return
    chunks = [ChunkId(r[0]) for r in con.execute("SELECT id FROM chunks ORDER BY id")]
    for chunk in chunks:
        if raft_sql.length(con, chunk) == 0:
            rebuild(con, path, chunk)
    con.execute("INSERT OR IGNORE INTO meta VALUES (?, '1')", (LINKED,))


# -- what comparing chains with other holders found -------------------------------------
def diverged(con: sqlite3.Connection, found: Divergence) -> None:
    """Record (or replace) a divergence of the chunk's chain from a peer's."""
    con.execute(
        "INSERT OR REPLACE INTO chain_diverged (chunk_id, peer_id, position, detail, noticed) "
        "VALUES (?, ?, ?, ?, ?)",
        (found.chunk, found.peer, found.position, found.detail, found.noticed or time.time()),
    )


def agreed(con: sqlite3.Connection, chunk: ChunkId, peer: PeerId, position: int) -> None:
    """Forget a divergence from `peer` at or before `position` of the chunk's chain."""
    con.execute(
        "DELETE FROM chain_diverged WHERE chunk_id = ? AND peer_id = ? AND position <= ?",
        (chunk, peer, position),
    )


def forget(con: sqlite3.Connection, chunk: ChunkId) -> None:
    """Forget every divergence of the chunk (its replica was replaced)."""
    con.execute("DELETE FROM chain_diverged WHERE chunk_id = ?", (chunk,))


def divergences(con: sqlite3.Connection) -> list[Divergence]:
    """Every recorded divergence, by chunk and peer."""
    return [
        Divergence(ChunkId(chunk), PeerId(peer), position, detail, noticed)
        for chunk, peer, position, detail, noticed in con.execute(
            "SELECT chunk_id, peer_id, position, detail, noticed FROM chain_diverged "
            "ORDER BY chunk_id, peer_id"
        )
    ]
