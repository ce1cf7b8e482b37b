"""`mapctl bench lookup`: Chord lookup hops and latency on a ring of N nodes (issue 4 §6).

N `ChordNode`s, each on its own real `Rpc` over `ZmqTransport` bound to
127.0.0.1 port 0, all in this process and one event loop, as in
`tests/swarm/test_chord.py`. Nodes join one by one through a random earlier
node; the benchmark then drives stabilize / check-predecessor rounds itself
until every successor list and predecessor matches the `SortedRing` oracle,
fixes every finger table once, and checks the fingers against the oracle too,
all within a bound on rounds. It then times L lookups of random keys, one at a
time, each from a random node, and checks every answer against the oracle.

Nothing here asserts a speed; the figures go to docs/benchmarks.md. The Chord
paper (Stoica et al., SIGCOMM 2001, §6) measures a mean path length of about
½·log2 N, so our target is ``target_mean_hops(N) = ½·log2 N + 1`` (hops count
requests to other nodes; the first step is the asking node's own table).
Latency is wall time on one event loop that also serves every other node, and
includes opening the zmq connection the first time one node asks another, as
an iterative lookup asks nodes outside the asker's finger table.
"""

from __future__ import annotations

import asyncio
import logging
import math
import os
import random
import statistics
import time
from collections.abc import Awaitable, Callable, Sequence
from typing import Any

from mapapi.bench.swarm import _environment, percentile
from mapapi.dht.chord import ChordNode
from mapapi.dht.ring import RING_SIZE, SortedRing
from mapapi.errors import MapError, NetworkError
from mapapi.ids import PeerId
from mapapi.net import Rpc, ZmqTransport

log = logging.getLogger(__name__)

DEFAULT_LOOKUPS = 1000
"""Lookups per ring: at N = 128 they take about a second, the ring's setup much longer."""

SWEEP = (8, 16, 32, 64, 128)
"""The ring sizes of `mapctl bench lookup --sweep`."""

SUCCESSORS = 4  # successor list length, as the peers use
TIMEOUT = 2.0  # seconds per request; no node dies here, so only a bug reaches it


class RingNotStable(MapError):
    """The benchmark's ring did not match the oracle within its bound on rounds."""


def target_mean_hops(peers: int) -> float:
    """The mean hops we aim for on a ring of `peers` nodes: ½·log2 N + 1."""
    return 0.5 * math.log2(peers) + 1


def environment() -> dict[str, Any]:
    """The machine, Python and 1-minute load a plot's caption names: call it before
    the runs, whose own load would count otherwise."""
    return _environment(use_uvloop=False, load=os.getloadavg()[0])


def measure_lookups(
    peers: int,
    lookups: int = DEFAULT_LOOKUPS,
    *,
    seed: int = 0,
    max_rounds: int | None = None,
) -> dict[str, Any]:
    """Build a ring of `peers` nodes in this process and time `lookups` lookups.

    Args:
        peers: nodes on the ring.
        lookups: random-key lookups to time, each from a random node.
        seed: seeds the node ids, the join order and the keys, so the hop
            counts of a run can be reproduced (its latencies cannot).
        max_rounds: bound on stabilize rounds (default ``2 * peers + 10``).

    Returns:
        JSON-ready figures: ``peers``, ``lookups``, ``mean_hops``,
        ``target_mean_hops``, ``p99_hops``, ``p50_ms``, ``p99_ms``, ``errors``
        (answers that differ from the oracle, and lookups that failed with a
        `NetworkError`; neither counts in the other figures) and ``setup_s``
        (building and converging the ring). The hop and latency figures are
        None when no lookup succeeded.

    Raises:
        RingNotStable: the ring did not match the oracle within `max_rounds`.
        ValueError: `peers` or `lookups` is below 1.
    """
    if peers < 1 or lookups < 1:
        raise ValueError(f"need at least 1 peer and 1 lookup, got {peers} and {lookups}")
    return asyncio.run(_measure(peers, lookups, random.Random(seed), max_rounds or 2 * peers + 10))


async def _measure(peers: int, lookups: int, rng: random.Random, max_rounds: int) -> dict[str, Any]:
    nodes: list[ChordNode] = []
    started = time.perf_counter()
    try:
        await _build(nodes, peers, rng)
        rounds = await _converge(nodes, max_rounds)
        setup = time.perf_counter() - started
        log.info("ring of %d nodes stable after %d rounds, %.1f s", peers, rounds, setup)
        hops, millis, errors = await _time_lookups(nodes, lookups, rng)
    finally:
        await asyncio.gather(*(node.rpc.close() for node in nodes))
    return {
        "peers": peers,
        "lookups": lookups,
        "mean_hops": round(statistics.fmean(hops), 3) if hops else None,
        "target_mean_hops": round(target_mean_hops(peers), 3),
        "p99_hops": percentile(hops, 0.99) if hops else None,
        "p50_ms": round(percentile(millis, 0.5), 3) if millis else None,
        "p99_ms": round(percentile(millis, 0.99), 3) if millis else None,
        "errors": errors,
        "setup_s": round(setup, 2),
    }


async def _build(nodes: list[ChordNode], peers: int, rng: random.Random) -> None:
    """Start `peers` nodes into `nodes` (so the caller closes them whatever happens)
    and join each through a random earlier one."""
    for _ in range(peers):
        peer_id = PeerId(f"{rng.getrandbits(128):032x}")
        rpc = Rpc(ZmqTransport(peer_id))
        try:
            await rpc.start("tcp://127.0.0.1:0")
        except BaseException:
            await rpc.close()
            raise
        # The periodic tasks are never started (`start()`): the benchmark drives
        # every round itself, so the ring is still while lookups are timed.
        node = ChordNode(rpc, peer_id, successors=SUCCESSORS, timeout=TIMEOUT)
        if nodes:
            await node.join(rng.choice(nodes).me.address)
        nodes.append(node)


async def _converge(nodes: list[ChordNode], max_rounds: int) -> int:
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


async def _time_lookups(
    nodes: Sequence[ChordNode], count: int, rng: random.Random
) -> tuple[list[float], list[float], int]:
    """Time `count` lookups, one at a time so none queues behind another;
    returns the hops and milliseconds of the correct ones and the error count."""
    oracle = SortedRing(node.key for node in nodes)
    address = {node.key: node.me.address for node in nodes}
    hops: list[float] = []
    millis: list[float] = []
    errors = 0
    for _ in range(count):
        node, key = rng.choice(nodes), rng.randrange(RING_SIZE)
        began = time.perf_counter()
        try:
            owner, where, steps = await node.find_successor(key)
        except NetworkError as exc:
            errors += 1
            log.warning("lookup of %#x from %s failed: %s", key, node.me.address, exc)
            continue
        elapsed = time.perf_counter() - began
        if owner != oracle.successor(key) or where != address[owner]:
            errors += 1
            log.warning(
                "lookup of %#x from %s answered %#x, not %#x",
                key,
                node.me.address,
                owner,
                oracle.successor(key),
            )
            continue
        hops.append(steps)
        millis.append(elapsed * 1e3)
    return hops, millis, errors
