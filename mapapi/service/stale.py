"""Views that read this peer's replicas as they are (`view open --stale`; issue 13 §3).

A view begun now normally catches up the chunks it reads with their leaders
first (ReadIndex), so it sees every commit acknowledged anywhere. That needs a
leader to answer. A robot out of radio range, or an operator who wants an
answer now, can read what its replicas hold instead: no catch-up, no fetch of
a chunk not held here, nothing written to a chunk's log, and the answer says
how old the replicas may be (`Staleness`). A commit from such a view is checked
as any other: a change built on a stale read conflicts at its chunk's leader.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from mapapi.core.history import Revision
from mapapi.core.ids import ChunkId, ItemId
from mapapi.store.offload import off_loop

if TYPE_CHECKING:
    from mapapi.service.peer import Peer


@dataclass(frozen=True, slots=True)
class Staleness:
    """How old a peer's replicas may be: the newest commit time they hold, and the
    seconds since the longest-silent of their chunks' leaders last spoke to this
    peer (0 where this peer leads; None without a swarm: nothing newer exists
    that it could know of). A quiet group's leader says nothing while nothing
    changes, so the seconds are an upper bound on how old its replica is."""

    time: int
    silent_s: float | None

    def as_dict(self) -> dict[str, Any]:
        """The JSON form (`view open --stale --json`)."""
        silent = None if self.silent_s is None else round(self.silent_s, 1)
        return {"time": self.time, "leaders_silent_s": silent}


def staleness(peer: Peer) -> Staleness:
    """How old `peer`'s replicas may be (see `Staleness`)."""
    if peer.swarm is None:
        return Staleness(peer.store.clock(), None)
    ages = peer.swarm.groups.news_age().values()
    return Staleness(peer.store.clock(), max(ages, default=0.0))


class StaleReads:
    """A transaction backend over `peer` that reads its replicas as they are
    (see the module docstring); tables, local reads and commits are the peer's."""

    def __init__(self, peer: Peer) -> None:
        self._store = peer.store
        self.name = peer.name
        self.table = peer.table
        self.chunk_table = peer.chunk_table
        self.read_local = peer.read_local
        self.commit_transaction = peer.commit_transaction

    async def read(self, item_id: ItemId, time: int) -> Revision | None:
        """The local revision: an item of a chunk not held here is not fetched."""
        return self.read_local(item_id, time)

    async def scan(self, time: int, table: str, chunk: ChunkId | None) -> list[Revision]:
        """Items held here visible at `time` (in a worker thread)."""
        return await off_loop(self._store, self._store.scan, time, table=table, chunk=chunk)

    async def catch_up(self, time: int, **_where: object) -> int:
        """No catch-up: the view reads at `time`, the replicas' newest."""
        return time
