"""A still Chord ring of N nodes in this process, for benchmarks and tests.

Each node has its own real `Rpc` over `ZmqTransport` bound to 127.0.0.1 port
0, all on the caller's event loop. The nodes' periodic tasks are never
started: `build_ring` joins the nodes one by one through a random earlier
node, then drives stabilize / check-predecessor rounds itself until every
successor list and predecessor matches the `SortedRing` oracle, fixes every
finger table once and checks it against the oracle too. The ring then stays
exactly as it is while it is measured.
"""

from __future__ import annotations

import asyncio
import logging
import random
from collections.abc import AsyncIterator, Awaitable, Callable, Sequence
from contextlib import asynccontextmanager

from mapapi.core.errors import MapError
from mapapi.core.ids import PeerId
from mapapi.lookup.dht.chord import ChordNode
from mapapi.lookup.dht.ring import SortedRing
from mapapi.net import Rpc, Shaper, ZmqTransport

log = logging.getLogger(__name__)

SUCCESSORS = 4  # successor list length, as the peers use
TIMEOUT = 2.0  # seconds per request; no node dies here, so only a bug reaches it


class RingNotStable(MapError):
    """The ring did not match the oracle within the bound on rounds."""


@asynccontextmanager
async def still_ring(
    count: int,
    rng: random.Random,
    *,
    max_rounds: int | None = None,
    shaper: Callable[[], Shaper | None] = lambda: None,
) -> AsyncIterator[list[ChordNode]]:
    """`count` converged nodes (closed on exit, whatever happens).

    Args:
        count: nodes on the ring.
        rng: seeds the node ids and the join order.
        max_rounds: bound on stabilize rounds (default ``2 * count + 10``).
        shaper: makes each node's link shaping (simulated latency), or None.

    Raises:
        RingNotStable: the ring did not converge within `max_rounds`.
    """
    nodes: list[ChordNode] = []
    try:
        for _ in range(count):
            peer_id = PeerId(f"{rng.getrandbits(128):032x}")
            rpc = Rpc(ZmqTransport(peer_id, shaper=shaper()))
            try:
                await rpc.start("tcp://127.0.0.1:0")
            except BaseException:
                await rpc.close()
                raise
            node = ChordNode(rpc, peer_id, successors=SUCCESSORS, timeout=TIMEOUT)
            if nodes:
                await node.join(rng.choice(nodes).me.address)
            nodes.append(node)
        rounds = await converge(nodes, max_rounds or 2 * count + 10)
        log.info("ring of %d nodes stable after %d rounds", count, rounds)
        yield nodes
    finally:
        await asyncio.gather(*(node.rpc.close() for node in nodes))


async def converge(nodes: list[ChordNode], max_rounds: int) -> int:
    """Stabilize until the ring matches the oracle, then fix the fingers; returns
    the rounds taken.

    Raises:
        RingNotStable: not done within `max_rounds`.
    """
    oracle = SortedRing(node.key for node in nodes)
    for rounds in range(1, max_rounds + 1):
        if not _ring_ok(nodes, oracle):
            await _each(nodes, ChordNode.stabilize_once)
            await _each(nodes, ChordNode.check_predecessor_once)
            continue
        # Lookups are exact once successor lists are, so one pass of
        # fix_fingers should fill every table; the check guards against a bug.
        await _each(nodes, ChordNode.fix_fingers_once)
        if _fingers_ok(nodes, oracle):
            return rounds
    raise RingNotStable(
        f"the ring of {len(nodes)} nodes did not match the sorted-ring oracle after "
        f"{max_rounds} rounds: a Chord bug; reproduce with tests/swarm/test_chord.py"
    )


async def _each(nodes: Sequence[ChordNode], step: Callable[[ChordNode], Awaitable[None]]) -> None:
    """Run one maintenance step on every node at once, as the periodic tasks would.

    A `MapError` of one node is logged and left to the next round to repair (as
    `ChordNode._every` does); anything else is a bug and propagates.
    """
    results = await asyncio.gather(*(step(node) for node in nodes), return_exceptions=True)
    for node, result in zip(nodes, results, strict=True):
        if isinstance(result, MapError):
            log.debug("%s failed on %s: %s", step.__name__, node.me.address, result)
        elif isinstance(result, BaseException):
            raise result


def _ring_ok(nodes: Sequence[ChordNode], oracle: SortedRing) -> bool:
    return all(
        [s.key for s in node.successors] == oracle.successor_list(node.key, SUCCESSORS)
        and (node.predecessor or node.me).key == oracle.predecessor(node.key)
        for node in nodes
    )


def _fingers_ok(nodes: Sequence[ChordNode], oracle: SortedRing) -> bool:
    return all(
        [None if f is None else f.key for f in node.fingers] == oracle.finger_table(node.key)
        for node in nodes
    )
