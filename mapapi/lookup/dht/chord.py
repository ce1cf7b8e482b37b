"""`ChordNode`: one peer's place on the Chord ring, over its `Rpc` (DESIGN §7).

Routing follows the Chord paper (Stoica et al., SIGCOMM 2001): lookups are
iterative, each step asks a node for `ring.next_hop` over its fingers and
successor list, so a lookup takes O(log n) hops once fingers are fixed; the
periodic stabilize / fix-fingers / check-predecessor tasks repair the ring as
nodes join, leave and fail (`upkeep.RingUpkeep`). The node stores soft-state
sets (`values.RingValues` over `storage.Storage`): the owner of a key applies
`add` / `remove` itself, atomically, and copies the change to its successor
list; keys move to a newcomer when it notifies its successor, and to the
successor on a graceful `leave()`.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import Callable, Coroutine
from typing import Any, TypeVar

from mapapi.core.errors import MapError, NetworkError
from mapapi.core.ids import PeerId
from mapapi.lookup.dht import ring
from mapapi.lookup.dht.ring_wire import Node, key_bytes, key_from, node_of, wire
from mapapi.lookup.dht.storage import Storage
from mapapi.lookup.dht.upkeep import RingUpkeep
from mapapi.lookup.dht.values import MemberFilter, RingValues
from mapapi.net.codec import Kind
from mapapi.net.messages import (
    Ack,
    ChordAdd,
    ChordFindSuccessor,
    ChordGet,
    ChordGetNeighbours,
    ChordHop,
    ChordLeave,
    ChordNeighbours,
    ChordNotify,
    ChordRemove,
    ChordStore,
)
from mapapi.net.rpc import Request, Rpc

log = logging.getLogger(__name__)

T = TypeVar("T")

_MAX_HOPS = 2 * ring.RING_BITS
_ATTEMPTS = 4
_NOBODY = PeerId("00" * 16)  # the sender of a request a node serves to itself


class ChordNode:
    """This peer on the ring; registers its `rpc_*` handlers on `rpc` (started).

    Args:
        rpc: the peer's Rpc endpoint, already listening; the node does not own it.
        peer_id: this peer; its ring key is `ring.peer_key(peer_id)`.
        successors: length of the successor list (also the replication factor).
        stabilize_period, fix_fingers_period, check_predecessor_period: seconds
            between rounds of the periodic tasks started by `start()`.
        timeout: deadline in seconds of each request to another node.
        clock: seconds on a monotonic clock, for time-to-live (injectable in tests).
    """

    def __init__(
        self,
        rpc: Rpc,
        peer_id: PeerId,
        *,
        successors: int = 4,
        stabilize_period: float = 1.0,
        fix_fingers_period: float = 5.0,
        check_predecessor_period: float = 2.0,
        timeout: float = 2.0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if successors < 1:
            raise ValueError(f"a successor list holds at least 1 node, got {successors}")
        self.rpc = rpc
        self.me = Node(ring.peer_key(peer_id), rpc.address)
        self.predecessor: Node | None = None
        self.successors: list[Node] = [self.me]
        self.fingers: list[Node | None] = [None] * ring.RING_BITS
        self.storage = Storage()
        self.clock = clock
        self.timeout = timeout
        self.k = successors  # the successor list's length, also the replication factor
        self._periods = (stabilize_period, fix_fingers_period, check_predecessor_period)
        self._suspects: dict[int, float] = {}  # key -> until (real time): found dead
        self._tasks: list[asyncio.Task[None]] = []
        self._round = asyncio.Event()  # set (and replaced) after each periodic step
        self.values = RingValues(self)
        self.upkeep = RingUpkeep(self)
        self.requests_sent = 0  # to other nodes, for benchmarks (paper Fig. 8)
        self._handlers: dict[type, Callable[[Request], Any]] = {
            ChordFindSuccessor: self.rpc_find_successor,
            ChordGetNeighbours: self.rpc_get_neighbours,
            ChordNotify: self.rpc_notify,
            ChordLeave: self.rpc_leave,
            ChordAdd: self.values.rpc_add,
            ChordRemove: self.values.rpc_remove,
            ChordGet: self.values.rpc_get,
            ChordStore: self.values.rpc_store,
        }
        for body, handler in self._handlers.items():
            rpc.register(body, self._proof_of_life(handler))

    @property
    def key(self) -> int:
        """This node's ring key."""
        return self.me.key

    def readdress(self, address: str) -> None:
        """Be reached at `address` instead of the Rpc's bound one (before joining:
        a wildcard host is no address other nodes can reach)."""
        alone = self.successors == [self.me]
        self.me = Node(self.key, address)
        if alone:
            self.successors = [self.me]

    # -- lifecycle -------------------------------------------------------------------
    def start(self) -> None:
        """Start the periodic stabilize, fix-fingers and check-predecessor tasks."""
        steps = (self.stabilize_once, self.fix_fingers_once, self.check_predecessor_once)
        for period, step in zip(self._periods, steps, strict=True):
            name = f"chord {step.__name__} {self.me.address}"
            self._tasks.append(
                asyncio.get_running_loop().create_task(self._every(period, step), name=name)
            )

    async def _every(self, period: float, step: Callable[[], Coroutine[Any, Any, object]]) -> None:
        while True:
            await asyncio.sleep(period)
            try:
                await step()
            except MapError as exc:  # a dead neighbour: the next round repairs it
                log.debug("%s failed on %s: %s", step.__name__, self.me.address, exc)
            done, self._round = self._round, asyncio.Event()
            done.set()

    async def next_round(self) -> None:
        """Wait until one of the periodic tasks (started by `start()`) ends a step."""
        await self._round.wait()

    async def close(self) -> None:
        """Cancel and await the periodic tasks (the Rpc stays open). Idempotent."""
        for task in self._tasks:
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        self._tasks.clear()

    async def join(self, address: str) -> None:
        """Join the ring through the member at `address`.

        Raises:
            NetworkError: the member did not answer in time.
        """
        successor, _ = await self.lookup(self.key, Node(0, address), retry=False)
        self.predecessor = None
        self.successors = [successor]
        await self.stabilize_once()

    async def merge_through(self, address: str) -> bool:
        """Look this node's own key up on the ring of the node at `address`; if that
        ring has a node between us and our successor, make it our successor.
        After a partition healed, the two rings the halves repaired into know
        nothing of each other: this step, run now and then through a random
        member, joins them into one again, stabilize doing the rest (the
        repair a joining node gets). Returns whether our successor changed.

        Raises:
            NetworkError: the member did not answer in time.
        """
        found, _ = await self.lookup(self.key, Node(0, address), retry=False)
        successor = self.successors[0]
        if found == self.me or found == successor:
            return False
        if successor != self.me and not ring.in_interval(
            found.key, self.key, successor.key, inclusive_right=False
        ):
            return False
        self._suspects.pop(found.key, None)
        self.successors = [found, *(s for s in self.successors if s != found)][: self.k]
        return True

    async def leave(self) -> None:
        """Leave gracefully: stop the tasks, hand every value to the successor and
        tell the predecessor and successor who replaces this node."""
        await self.close()
        pred = () if self.predecessor is None else (wire(self.predecessor),)
        entries = self.values.entries()
        for successor in [s for s in self.successors if s != self.me]:
            bye = ChordLeave(wire(self.me), pred, ())
            try:
                await self.call(successor, ChordStore(entries, replicate=True), Ack)
                await self.call(successor, bye, Ack)
                break
            except NetworkError:
                continue
        if self.predecessor is not None and self.predecessor != self.me:
            rest = tuple(wire(s) for s in self.successors if s != self.predecessor)
            with contextlib.suppress(NetworkError):
                await self.call(self.predecessor, ChordLeave(wire(self.me), (), rest), Ack)
        self.predecessor, self.successors = None, [self.me]

    # -- lookups -----------------------------------------------------------------------
    async def find_successor(self, key: int) -> tuple[int, str, int]:
        """The node storing `key`: ``(node key, address, hops)``; hops count requests.

        Raises:
            NetworkError: no live route to the key after a few attempts.
            ValueError: `key` is not a ring key.
        """
        if isinstance(key, bool) or not isinstance(key, int) or not 0 <= key < ring.RING_SIZE:
            raise ValueError(f"a ring key is an int in [0, 2**{ring.RING_BITS}), got {key!r}")
        node, hops = await self.lookup(key, self.me)
        return node.key, node.address, hops

    async def lookup(self, key: int, start: Node, *, retry: bool = True) -> tuple[Node, int]:
        avoid = self._suspected()
        error: NetworkError | None = None
        for _ in range(_ATTEMPTS if retry else 1):
            current, hops = start, 0
            while hops < _MAX_HOPS:
                if current == self.me:
                    hop = self._next_hop(key, avoid)
                else:
                    ask = ChordFindSuccessor(key_bytes(key), tuple(key_bytes(a) for a in avoid))
                    try:
                        reply = await self.call(current, ask, ChordHop)
                    except NetworkError as exc:
                        if not retry:
                            raise
                        error = exc
                        avoid.add(self.suspect(current))
                        break
                    hops += 1
                    current = node_of(reply.node)
                    if reply.final:
                        return current, hops
                    continue
                if hop.final:
                    return self._known(hop.node), hops
                current = self._known(hop.node)
            else:
                error = NetworkError(f"lookup of {key:#x} did not converge in {_MAX_HOPS} hops")
        raise error or NetworkError(f"no live route to {key:#x}")

    def _next_hop(self, key: int, avoid: set[int]) -> ring.Hop:
        successors = [s.key for s in self.successors if s.key not in avoid] or [self.key]
        fingers = {f.key for f in self.fingers if f is not None and f.key not in avoid}
        return ring.next_hop(self.key, key, successors, fingers)

    def _known(self, key: int) -> Node:
        for node in (self.me, *self.successors, *self.fingers):
            if node is not None and node.key == key:
                return node
        raise LookupError(f"{key:#x} is not a node this node knows")  # unreachable

    def suspect(self, node: Node) -> int:
        """Forget a node that did not answer (found dead) for a while."""
        self._suspects[node.key] = time.monotonic() + 10 * max(self._periods)
        self.fingers = [None if f == node else f for f in self.fingers]
        self.successors = [s for s in self.successors if s != node] or [self.me]
        if self.predecessor == node:
            self.predecessor = None
        return node.key

    def forget(self, address: str) -> None:
        """Route around the node at `address` for a while: it left (its peer said
        Bye), so its place in our fingers and successor list is stale."""
        for node in {n for n in (*self.successors, *self.fingers) if n is not None}:
            if node.address == address and node != self.me:
                self.suspect(node)
        if self.predecessor is not None and self.predecessor.address == address:
            self.suspect(self.predecessor)

    def _suspected(self) -> set[int]:
        now = time.monotonic()
        self._suspects = {k: until for k, until in self._suspects.items() if until > now}
        return set(self._suspects)

    # -- periodic maintenance (`RingUpkeep`, Chord paper Fig. 7) -------------------------
    async def stabilize_once(self) -> None:
        """One stabilize round (`RingUpkeep.stabilize_once`)."""
        await self.upkeep.stabilize_once()

    async def fix_fingers_once(self) -> None:
        """Recompute the whole finger table (`RingUpkeep.fix_fingers_once`)."""
        await self.upkeep.fix_fingers_once()

    async def check_predecessor_once(self) -> None:
        """Forget a dead predecessor; drop expired values."""
        await self.upkeep.check_predecessor_once()

    # -- values (`RingValues`) --------------------------------------------------------------
    async def add(self, key: int, member: bytes, ttl: float) -> None:
        """Add `member` to the set under `key` for `ttl` seconds (`RingValues.add`)."""
        await self.values.add(key, member, ttl)

    async def remove(self, key: int, member: bytes) -> None:
        """Remove `member` from the set under `key`."""
        await self.values.remove(key, member)

    def register_filter(self, name: str, member_filter: MemberFilter) -> None:
        """Let `get(key, filter=name, ...)` keep only what `member_filter` passes
        (`RingValues.register_filter`)."""
        self.values.register_filter(name, member_filter)

    async def get(self, key: int, filter: str = "", argument: bytes = b"") -> set[bytes]:
        """The live members under `key` (`RingValues.get`)."""
        return await self.values.get(key, filter, argument)

    # -- handlers --------------------------------------------------------------------------
    def _proof_of_life(self, handler: Callable[[Request], Any]) -> Callable[[Request], Any]:
        """`handler`, after clearing any suspicion of the requesting node: it is alive."""

        def serve(req: Request) -> Any:
            self._suspects.pop(ring.peer_key(req.sender), None)
            return handler(req)

        return serve

    async def call(self, node: Node, body: object, expect: type[T]) -> T:
        if node == self.me:  # served locally, as a remote would
            request = Request(_NOBODY, 0, 0, Kind.REQUEST, body)
            result = self._handlers[type(body)](request)
            if asyncio.iscoroutine(result):
                result = await result
            assert isinstance(result, expect)
            return result
        self.requests_sent += 1
        reply = await self.rpc.request(node.address, body, timeout=self.timeout, expect=expect)
        # It answered: a suspicion was wrong (a slow reply timed out before), and
        # routing around a live node would give some lookups the wrong owner.
        self._suspects.pop(node.key, None)
        return reply

    def rpc_find_successor(self, req: Request) -> ChordHop:
        """One lookup step: the key's successor, or the next node to ask."""
        body: ChordFindSuccessor = req.body
        hop = self._next_hop(key_from(body.key), {key_from(a) for a in body.avoid})
        return ChordHop(wire(self._known(hop.node)), hop.final)

    def rpc_get_neighbours(self, req: Request | None = None) -> ChordNeighbours:
        """This node's predecessor and successor list."""
        pred = () if self.predecessor is None else (wire(self.predecessor),)
        return ChordNeighbours(pred, tuple(wire(s) for s in self.successors))

    async def rpc_notify(self, req: Request) -> Ack:
        """A node might be our predecessor; if it is, hand it the keys it now owns."""
        node = node_of(req.body.node)
        old = self.predecessor
        if node == self.me or not (
            old is None or ring.in_interval(node.key, old.key, self.key, inclusive_right=False)
        ):
            return Ack()
        # Hand the keys over first: until `node` is our predecessor, nobody routes
        # to it (our predecessor adopts it from our answer), so no lookup can
        # reach it before it holds them.
        entries = self.values.entries(lambda k: not ring.responsible(k, self.key, node.key))
        if entries:
            await self.call(node, ChordStore(entries), Ack)
            old = self.predecessor  # another node may have notified meanwhile
            if old is not None and not ring.in_interval(
                node.key, old.key, self.key, inclusive_right=False
            ):
                return Ack()
        self.predecessor = node
        self._suspects.pop(node.key, None)
        if self.successors == [self.me]:
            self.successors = [node]  # a second node: it is our successor too
        return Ack()

    async def rpc_leave(self, req: Request) -> Ack:
        """A neighbour leaves: take its predecessor, or splice in its successors and
        pass the news to our predecessor, whose list may hold it too (at most k hops)."""
        body: ChordLeave = req.body
        gone = node_of(body.node)
        if self.predecessor == gone:
            self.predecessor = node_of(body.predecessor[0]) if body.predecessor else None
        self.fingers = [None if f == gone else f for f in self.fingers]
        if self.predecessor == self.me:
            self.predecessor = None
        if gone not in self.successors:
            return Ack()
        rest = [node_of(p) for p in body.successors]
        merged = [s for s in self.successors[: self.successors.index(gone)] + rest if s != self.me]
        self.successors = list(dict.fromkeys(merged))[: self.k] or [self.me]
        pred = self.predecessor
        if pred is not None and pred != gone and body.successors:
            with contextlib.suppress(NetworkError):
                await self.call(pred, ChordLeave(body.node, (), body.successors), Ack)
        return Ack()
