"""The Raft state of each chunk's group in the SQLite store (DESIGN §13).

Per chunk: the hard state (term, vote, commit index), the index applied to the
store's revisions and the newest commit time they brought (the chunk's clock,
which every holder derives from the same log), the last snapshot's metadata,
the log after it, the multi-chunk transactions the log prepared or decided
(two-phase commit), and the hash chain of the commits the log applied
(`core/chain.py`: one link per commit, the last one the chunk's head). Kept in
the same file as the revisions so that an entry's effect and the applied index
move in one SQL transaction (`SqliteStore.exclusive`): after a crash nothing is
applied twice and nothing applied is forgotten.

Functions take a connection inside a write transaction the caller holds; they
know rows, not Raft (node ids and entry kinds are plain integers here).
"""

from __future__ import annotations

import sqlite3
from collections.abc import Sequence

from mapapi.store.base import LogRow, RaftRecord, TxRow

RAFT_SCHEMA = """
CREATE TABLE IF NOT EXISTS raft_state (
    chunk_id TEXT PRIMARY KEY, term INTEGER NOT NULL DEFAULT 0,
    vote INTEGER NOT NULL DEFAULT 0, commit_index INTEGER NOT NULL DEFAULT 0,
    applied INTEGER NOT NULL DEFAULT 0, snap_index INTEGER NOT NULL DEFAULT 0,
    snap_term INTEGER NOT NULL DEFAULT 0, snap_config BLOB NOT NULL DEFAULT x'',
    snap_data BLOB NOT NULL DEFAULT x'', time INTEGER NOT NULL DEFAULT 0);
CREATE TABLE IF NOT EXISTS raft_chain (
    chunk_id TEXT NOT NULL, seq INTEGER NOT NULL, commit_id TEXT NOT NULL, link BLOB NOT NULL,
    PRIMARY KEY (chunk_id, seq)) WITHOUT ROWID;
CREATE TABLE IF NOT EXISTS raft_tx (
    chunk_id TEXT NOT NULL, commit_id TEXT NOT NULL, state TEXT NOT NULL,
    time INTEGER NOT NULL, data BLOB NOT NULL,
    PRIMARY KEY (chunk_id, commit_id)) WITHOUT ROWID;
CREATE TABLE IF NOT EXISTS raft_log (
    chunk_id TEXT NOT NULL, idx INTEGER NOT NULL, term INTEGER NOT NULL,
    kind INTEGER NOT NULL, data BLOB NOT NULL,
    PRIMARY KEY (chunk_id, idx)) WITHOUT ROWID;
"""


def load(con: sqlite3.Connection, chunk: str) -> RaftRecord | None:
    """The stored state of `chunk`'s group, or None if this peer never persisted one."""
    row = con.execute(
        "SELECT term, vote, commit_index, applied, snap_index, snap_term, snap_config, "
        "snap_data, time FROM raft_state WHERE chunk_id = ?",
        (chunk,),
    ).fetchone()
    if row is None:
        return None
    entries = tuple(
        LogRow(index, term, kind, bytes(data))
        for index, term, kind, data in con.execute(
            "SELECT idx, term, kind, data FROM raft_log WHERE chunk_id = ? ORDER BY idx", (chunk,)
        )
    )
    term, vote, commit, applied, snap_index, snap_term, snap_config, snap_data, time = row
    return RaftRecord(
        term,
        vote,
        commit,
        applied,
        snap_index,
        snap_term,
        bytes(snap_config),
        bytes(snap_data),
        entries,
        time,
    )


def save(
    con: sqlite3.Connection,
    chunk: str,
    *,
    hard: tuple[int, int, int] | None = None,
    entries: Sequence[LogRow] = (),
    snapshot: tuple[int, int, bytes, bytes] | None = None,
    compacted: bool = False,
) -> None:
    """Persist one `Ready`'s worth of state, in the Ready order contract's order:
    the snapshot (it replaces the whole stored log), then the entries (the first
    replaces every stored entry from its index on), then the hard state.

    Args:
        hard: (term, vote, commit index).
        snapshot: (index, term, config bytes, data bytes).
        compacted: the snapshot is this replica's own state at an applied index
            (compaction): it replaces only the entries up to it, and only if it is
            newer than the stored one (a leader's may have arrived meanwhile).
    """
    con.execute("INSERT OR IGNORE INTO raft_state (chunk_id) VALUES (?)", (chunk,))
    if snapshot is not None and compacted:
        index, term, config, data = snapshot
        updated = con.execute(
            "UPDATE raft_state SET snap_index = ?, snap_term = ?, snap_config = ?, snap_data = ? "
            "WHERE chunk_id = ? AND snap_index < ?",
            (index, term, config, data, chunk, index),
        )
        if updated.rowcount:
            con.execute("DELETE FROM raft_log WHERE chunk_id = ? AND idx <= ?", (chunk, index))
    elif snapshot is not None:
        index, term, config, data = snapshot
        con.execute(
            "UPDATE raft_state SET snap_index = ?, snap_term = ?, snap_config = ?, snap_data = ?, "
            "commit_index = MAX(commit_index, ?) WHERE chunk_id = ?",
            (index, term, config, data, index, chunk),
        )
        # A leader's snapshot replaces the whole log: entries after it may be a branch
        # that lost (simulator seed 81); the leader sends what follows it.
        con.execute("DELETE FROM raft_log WHERE chunk_id = ?", (chunk,))
    if entries:
        con.execute(
            "DELETE FROM raft_log WHERE chunk_id = ? AND idx >= ?", (chunk, entries[0].index)
        )
        con.executemany(
            "INSERT INTO raft_log (chunk_id, idx, term, kind, data) VALUES (?, ?, ?, ?, ?)",
            [(chunk, e.index, e.term, e.kind, e.data) for e in entries],
        )
    if hard is not None:
        con.execute(
            "UPDATE raft_state SET term = ?, vote = ?, commit_index = ? WHERE chunk_id = ?",
            (*hard, chunk),
        )


def set_applied(con: sqlite3.Connection, chunk: str, index: int, time: int = 0) -> None:
    """Record that the store's revisions reflect `chunk`'s log up to `index`, whose
    newest commit time is `time` (the chunk's clock only moves forward).

    Raises:
        ValueError: `index` goes backwards (an entry would be applied twice).
    """
    row = con.execute("SELECT applied FROM raft_state WHERE chunk_id = ?", (chunk,)).fetchone()
    if row is None:
        raise ValueError(f"chunk {chunk} has no Raft state to apply to")
    if index < row[0]:
        raise ValueError(f"chunk {chunk}: applied index {index} is behind {row[0]}")
    con.execute(
        "UPDATE raft_state SET applied = ?, time = MAX(time, ?) WHERE chunk_id = ?",
        (index, time, chunk),
    )


def applied_index(con: sqlite3.Connection, chunk: str) -> int | None:
    """`chunk`'s applied log index, or None if it has no Raft state."""
    row = con.execute("SELECT applied FROM raft_state WHERE chunk_id = ?", (chunk,)).fetchone()
    return None if row is None else int(row[0])


def chunk_time(con: sqlite3.Connection, chunk: str) -> int:
    """The newest commit time applied from `chunk`'s log (0 if none)."""
    row = con.execute("SELECT time FROM raft_state WHERE chunk_id = ?", (chunk,)).fetchone()
    return 0 if row is None else int(row[0])


def drop(con: sqlite3.Connection, chunk: str) -> None:
    """Forget `chunk`'s group (this peer no longer holds the chunk). Its hash chain
    stays: it is the replica's (`chain_sql`), linked on every commit path."""
    con.execute("DELETE FROM raft_log WHERE chunk_id = ?", (chunk,))
    con.execute("DELETE FROM raft_tx WHERE chunk_id = ?", (chunk,))
    con.execute("DELETE FROM raft_state WHERE chunk_id = ?", (chunk,))


RAFT_TABLES = ("raft_state", "raft_log", "raft_chain", "raft_tx")
"""The tables above; an older store gains the ones it lacks."""


def tx_get(con: sqlite3.Connection, chunk: str, commit_id: str) -> TxRow | None:
    """What `chunk`'s log recorded of a multi-chunk transaction, or None."""
    row = con.execute(
        "SELECT state, time, data FROM raft_tx WHERE chunk_id = ? AND commit_id = ?",
        (chunk, commit_id),
    ).fetchone()
    return None if row is None else TxRow(row[0], int(row[1]), bytes(row[2]))


def tx_put(con: sqlite3.Connection, chunk: str, commit_id: str, row: TxRow) -> None:
    """Record (or replace) what `chunk`'s log decided of a transaction."""
    con.execute(
        "INSERT OR REPLACE INTO raft_tx (chunk_id, commit_id, state, time, data) "
        "VALUES (?, ?, ?, ?, ?)",
        (chunk, commit_id, row.state, row.time, row.data),
    )


def tx_rows(con: sqlite3.Connection, chunk: str, prepared: bool) -> list[tuple[str, TxRow]]:
    """The transactions `chunk`'s log recorded (only those not decided yet, if `prepared`)."""
    return [
        (commit_id, TxRow(state, int(time), bytes(data)))
        for commit_id, state, time, data in con.execute(
            "SELECT commit_id, state, time, data FROM raft_tx "
            "WHERE chunk_id = ? AND (state = 'prepared' OR NOT ?) ORDER BY commit_id",
            (chunk, prepared),
        )
    ]


def add_link(con: sqlite3.Connection, chunk: str, commit_id: str, link: bytes) -> None:
    """Append the chain link of a commit `chunk`'s log applied."""
    con.execute(
        "INSERT INTO raft_chain (chunk_id, seq, commit_id, link) VALUES (?, "
        "(SELECT COALESCE(MAX(seq), 0) + 1 FROM raft_chain WHERE chunk_id = ?), ?, ?)",
        (chunk, chunk, commit_id, link),
    )


def head(con: sqlite3.Connection, chunk: str) -> bytes | None:
    """The newest link of `chunk`'s chain, or None before its first commit."""
    row = con.execute(
        "SELECT link FROM raft_chain WHERE chunk_id = ? ORDER BY seq DESC LIMIT 1", (chunk,)
    ).fetchone()
    return None if row is None else bytes(row[0])


def links(con: sqlite3.Connection, chunk: str) -> list[tuple[str, bytes]]:
    """(commit id, link) of every commit of `chunk`'s chain, oldest first."""
    return [
        (commit_id, bytes(link))
        for commit_id, link in con.execute(
            "SELECT commit_id, link FROM raft_chain WHERE chunk_id = ? ORDER BY seq", (chunk,)
        )
    ]


def link_at(con: sqlite3.Connection, chunk: str, seq: int) -> bytes | None:
    """The link of `chunk`'s `seq`-th commit (from 1), or None if it has fewer."""
    row = con.execute(
        "SELECT link FROM raft_chain WHERE chunk_id = ? AND seq = ?", (chunk, seq)
    ).fetchone()
    return None if row is None else bytes(row[0])


def length(con: sqlite3.Connection, chunk: str) -> int:
    """How many commits `chunk`'s chain links."""
    row = con.execute("SELECT MAX(seq) FROM raft_chain WHERE chunk_id = ?", (chunk,)).fetchone()
    return int(row[0] or 0)
