"""The verifiable-history part of `SqliteStore` (issue 18 §3): each chunk's hash
chain (`chain_sql`), what comparing it with other holders found, and how the
store stands against its high-water mark (`mark`).

A base class of `SqliteStore` rather than a module of functions: these are
methods of the `ReplicaStore` protocol, on the store's connections.
"""

from __future__ import annotations

import sqlite3
from collections.abc import Callable
from contextlib import AbstractContextManager
from pathlib import Path

from mapapi.core.ids import ChunkId, CommitId, PeerId
from mapapi.store import chain_sql, compact_sql, raft_sql
from mapapi.store.base import Divergence, Rollback
from mapapi.store.mark import HighWater


class SqliteChains:
    """Chains, divergences and rollbacks of the store at `path` (see the module docstring)."""

    path: Path
    mark: HighWater
    _con: Callable[[], sqlite3.Connection]
    _write: Callable[[sqlite3.Connection], AbstractContextManager[None]]

    def chain_link(self, chunk_id: ChunkId, commit_id: CommitId, link: bytes) -> None:
        """Append a commit's link to the chunk's hash chain unless its head links that
        commit already (joins `exclusive()`)."""
        con = self._con()
        with self._write(con):
            chain_sql.add_link(con, chunk_id, commit_id, link)

    def chain_head(self, chunk_id: ChunkId) -> bytes | None:
        """The chunk's newest link, or None."""
        return raft_sql.head(self._con(), chunk_id)

    def chain_links(self, chunk_id: ChunkId) -> list[tuple[CommitId, bytes]]:
        """Every (commit, link) of the chunk's chain, oldest first."""
        return [(CommitId(c), link) for c, link in raft_sql.links(self._con(), chunk_id)]

    def chain_at(self, chunk_id: ChunkId, seq: int) -> bytes | None:
        """The link of the chunk's `seq`-th commit, or None."""
        return raft_sql.link_at(self._con(), chunk_id, seq)

    def chain_length(self, chunk_id: ChunkId) -> int:
        """How many commits the chunk's chain links."""
        return raft_sql.length(self._con(), chunk_id)

    def chain_base(self, chunk_id: ChunkId) -> list[tuple[CommitId, bytes]]:
        """The chain's compacted links, oldest first: those of commits some of whose
        revisions `mapctl gc` dropped, which the history can no longer rebuild."""
        return chain_sql.base(self._con(), chunk_id)

    def compact_history(self, horizon: int, keep: int | None = None) -> compact_sql.Compaction:
        """Drop the revisions no read at or after `horizon` sees, beyond each item's
        `keep` newest (`compact_sql`); the caller picks a horizon no reader began
        before. The file keeps its size: SQLite reuses the freed pages."""
        con = self._con()
        with self._write(con):
            return compact_sql.compact(con, horizon, keep)

    def history_floor(self) -> int:
        """The earliest time every revision is still here for (`compact_history`)."""
        return compact_sql.floor(self._con())

    def diverged(self, found: Divergence) -> None:
        """Record that a holder's chain of a chunk differs from this replica's."""
        con = self._con()
        with self._write(con):
            chain_sql.diverged(con, found)

    def agreed(self, chunk_id: ChunkId, peer: PeerId, position: int) -> None:
        """Forget a divergence from `peer` at or before `position`."""
        con = self._con()
        with self._write(con):
            chain_sql.agreed(con, chunk_id, peer, position)

    def divergences(self) -> list[Divergence]:
        """Every recorded divergence."""
        return chain_sql.divergences(self._con())

    def rollbacks(self) -> list[Rollback]:
        """How the store fell behind its high-water mark (`store/mark.py`)."""
        return self.mark.rollbacks(self._con())

    def accept_rollback(self) -> None:
        """Forget the recorded rollbacks and mark the store as it is now."""
        con = self._con()
        with self._write(con):
            self.mark.accept(con)
