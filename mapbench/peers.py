"""Swarms of settled peers in one process, for the benchmarks that measure
what peers send each other (`bench triggers`, `bench registration`).

Every peer is a real `Peer` on a `MemoryStore`, listening on 127.0.0.1 port 0,
joined through the first; the benchmark drives the Chord rounds itself until
the ring matches the sorted-ring oracle, and the periodic rounds and
announcement refreshes are parked (`STILL`), so traffic counters hold only
what a run itself costs.
"""

from __future__ import annotations

import random
from collections.abc import AsyncIterator, Callable
from contextlib import asynccontextmanager

from mapapi.core.ids import PeerId
from mapapi.lookup.spatial import SpatialGrid
from mapapi.maps.rules import map_rules
from mapapi.net.shaping import Shaper
from mapapi.net.stats import Stats
from mapapi.service.peer import Peer
from mapapi.store import MemoryStore
from mapapi.swarm.node import ChordOptions, Swarm
from mapbench.ring import converge

STILL = ChordOptions(
    stabilize=3600.0, fix_fingers=3600.0, check_predecessor=3600.0, holder_ttl=3600.0
)
"""The bench peers' Chord options: `settled_peers` settles the ring itself, and
no periodic round or refresh then falls inside a run."""


@asynccontextmanager
async def settled_peers(
    count: int,
    rng: random.Random,
    *,
    grid: SpatialGrid,
    chord: ChordOptions = STILL,
    shaper: Callable[[], Shaper | None] = lambda: None,
) -> AsyncIterator[list[Peer]]:
    """`count` in-memory peers on 127.0.0.1, port 0, joined through the first,
    once their Chord ring matches the sorted-ring oracle (`converge` drives the
    rounds itself); all closed on exit, whatever happens.

    Args:
        count: peers.
        rng: seeds their ids: one seed, one ring.
        grid: their spatial index.
        chord: their Chord options (the default parks the periodic rounds).
        shaper: makes each peer's link shaping (`mapapi.net.shaping`), or None.

    Raises:
        RingNotStable: the ring did not converge (a Chord bug).
    """
    peers: list[Peer] = []
    try:
        for _ in range(count):
            # the map tables' rules, as every peer of the application keeps them
            rules = map_rules()
            peer = Peer(
                MemoryStore(), PeerId(f"{rng.getrandbits(128):032x}"), grid=grid, rules=rules
            )
            peers.append(peer)
            await peer.start("tcp://127.0.0.1:0", chord=chord, shaper=shaper())
            if len(peers) > 1:
                await peer.join(peers[0].address)
        await converge([swarm_of(p).chord for p in peers], 2 * count + 10)
        yield peers
    finally:
        for peer in reversed(peers):
            await peer.close()


def swarm_of(peer: Peer) -> Swarm:
    """The swarm of a started peer."""
    assert peer.swarm is not None, "a peer of settled_peers is started"
    return peer.swarm


def stats_of(peer: Peer) -> Stats:
    """A started peer's traffic counters."""
    return swarm_of(peer).rpc.transport.stats


def received_bytes(peer: Peer) -> int:
    """Bytes a started peer received so far (requests and replies alike)."""
    return sum(t.bytes for t in stats_of(peer).received.values())
