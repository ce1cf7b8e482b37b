"""The periodic repair of one node's place on the Chord ring (Chord paper Fig. 7).

Stabilize asks the successor for its predecessor and adopts it if closer, then
refreshes the successor list and re-replicates to newcomers in it; fix-fingers
recomputes the finger table; check-predecessor forgets a dead predecessor.
`ChordNode` runs the rounds periodically (`start()`); tests run them one by one.
"""

from __future__ import annotations

import asyncio
from typing import TYPE_CHECKING

from mapapi.core.errors import NetworkError
from mapapi.lookup.dht import ring
from mapapi.lookup.dht.ring_wire import Node, node_of, wire
from mapapi.net.messages import Ack, ChordGetNeighbours, ChordNeighbours, ChordNotify

if TYPE_CHECKING:
    from mapapi.lookup.dht.chord import ChordNode


class RingUpkeep:
    """The maintenance rounds of `node`; one round of each kind at a time."""

    def __init__(self, node: ChordNode) -> None:
        self._node = node
        self._stabilizing = asyncio.Lock()
        self._fixing = asyncio.Lock()

    async def stabilize_once(self) -> None:
        """Ask the successor for its predecessor, adopt it if closer, notify the
        successor, refresh the successor list and re-replicate to newcomers in it."""
        async with self._stabilizing:
            successor, neighbours = await self._live_successor()
            pred = neighbours.predecessor
            if pred and ring.in_interval(
                node_of(pred[0]).key, self._node.key, successor.key, inclusive_right=False
            ):
                candidate = node_of(pred[0])
                try:
                    neighbours = await self._neighbours(candidate)
                    successor = candidate
                except NetworkError:
                    self._node.suspect(candidate)
            chain = [successor, *(node_of(p) for p in neighbours.successors)]
            fresh: list[Node] = []
            for node in chain:
                if node == self._node.me or len(fresh) == self._node.k:
                    break
                if node not in fresh:
                    fresh.append(node)
            self._node.successors = fresh or [self._node.me]
            if successor != self._node.me:
                await self._node.call(successor, ChordNotify(wire(self._node.me)), Ack)
            await self._node.values.replicate_to_new_successors()

    async def _live_successor(self) -> tuple[Node, ChordNeighbours]:
        for successor in list(self._node.successors):
            try:
                return successor, await self._neighbours(successor)
            except NetworkError:
                self._node.suspect(successor)
        return self._node.me, await self._neighbours(self._node.me)  # every successor is gone

    async def _neighbours(self, node: Node) -> ChordNeighbours:
        if node == self._node.me:
            return self._node.rpc_get_neighbours()
        return await self._node.call(node, ChordGetNeighbours(), ChordNeighbours)

    async def fix_fingers_once(self) -> None:
        """Recompute the whole finger table; finger `i` reuses finger `i-1` when its
        start falls before that node, so a round costs O(log n) lookups."""
        async with self._fixing:
            last: Node | None = None
            for i in range(ring.RING_BITS):
                start = ring.finger_start(self._node.key, i)
                if last is None or not ring.in_interval(
                    start, self._node.key, last.key, inclusive_right=True
                ):
                    last, _ = await self._node.lookup(start, self._node.me)
                self._node.fingers[i] = last

    async def check_predecessor_once(self) -> None:
        """Forget the predecessor if it does not answer; drop expired values."""
        self._node.storage.expire(self._node.clock())
        if self._node.predecessor is not None and self._node.predecessor != self._node.me:
            try:
                await self._neighbours(self._node.predecessor)
            except NetworkError:
                self._node.suspect(self._node.predecessor)
