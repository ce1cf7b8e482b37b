"""The verifiable-history part of `MemoryStore` (issue 18 §3): each chunk's hash
chain and what comparing it with other holders found (as `SqliteChains`). A
store in memory leaves no file behind to roll back: it has no high-water mark.
"""

from __future__ import annotations

import threading
import time

from mapapi.core.ids import ChunkId, CommitId, PeerId
from mapapi.store.base import Divergence, Rollback


class MemoryChains:
    """Chains and divergences kept in dicts, under the store's lock."""

    _lock: threading.RLock
    _chains: dict[ChunkId, list[tuple[CommitId, bytes]]]
    _compacted: dict[ChunkId, int]
    _diverged: dict[tuple[ChunkId, PeerId], Divergence]

    def chain_link(self, chunk_id: ChunkId, commit_id: CommitId, link: bytes) -> None:
        """Append a commit's link to the chunk's hash chain unless its head links that
        commit already."""
        with self._lock:
            chain = self._chains.setdefault(chunk_id, [])
            if not chain or chain[-1][0] != commit_id:
                chain.append((commit_id, link))

    def chain_head(self, chunk_id: ChunkId) -> bytes | None:
        """The chunk's newest link, or None."""
        with self._lock:
            chain = self._chains.get(chunk_id)
            return chain[-1][1] if chain else None

    def chain_links(self, chunk_id: ChunkId) -> list[tuple[CommitId, bytes]]:
        """Every (commit, link) of the chunk's chain, oldest first."""
        with self._lock:
            return list(self._chains.get(chunk_id, []))

    def chain_at(self, chunk_id: ChunkId, seq: int) -> bytes | None:
        """The link of the chunk's `seq`-th commit, or None."""
        with self._lock:
            chain = self._chains.get(chunk_id, [])
            return chain[seq - 1][1] if 0 < seq <= len(chain) else None

    def chain_length(self, chunk_id: ChunkId) -> int:
        """How many commits the chunk's chain links."""
        with self._lock:
            return len(self._chains.get(chunk_id, []))

    def chain_base(self, chunk_id: ChunkId) -> list[tuple[CommitId, bytes]]:
        """The chain's compacted links (a replica installed from a holder that ran
        `gc`; a store in memory never runs it itself)."""
        with self._lock:
            return self._chains.get(chunk_id, [])[: self._compacted.get(chunk_id, 0)]

    def history_floor(self) -> int:
        """0: a store in memory never drops history."""
        return 0

    def diverged(self, found: Divergence) -> None:
        """Record that a holder's chain of a chunk differs from this replica's."""
        with self._lock:
            noticed = found.noticed or time.time()
            self._diverged[(found.chunk, found.peer)] = Divergence(
                found.chunk, found.peer, found.position, found.detail, noticed
            )

    def agreed(self, chunk_id: ChunkId, peer: PeerId, position: int) -> None:
        """Forget a divergence from `peer` at or before `position`."""
        with self._lock:
            kept = self._diverged.get((chunk_id, peer))
            if kept is not None and kept.position <= position:
                del self._diverged[(chunk_id, peer)]

    def divergences(self) -> list[Divergence]:
        """Every recorded divergence."""
        with self._lock:
            return [self._diverged[k] for k in sorted(self._diverged)]

    def rollbacks(self) -> list[Rollback]:
        """None: nothing in memory can be rolled back behind the store's back."""
        return []

    def accept_rollback(self) -> None:
        """Nothing to accept."""
