"""`mapctl bench lookup`: Chord lookup hops and latency on a ring of N nodes (issue 4 §6).

N `ChordNode`s, each on its own real `Rpc` over `ZmqTransport` bound to
127.0.0.1 port 0, all in this process and one event loop, as in
`tests/swarm/test_chord.py`, built and converged by `mapbench.ring`
within a bound on rounds. It then times L lookups of random keys, one at a
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
from collections.abc import Sequence
from typing import Any

from mapapi.core.errors import NetworkError
from mapapi.lookup.dht.chord import ChordNode
from mapapi.lookup.dht.ring import RING_SIZE, SortedRing
from mapbench.ring import still_ring
from mapbench.swarm import environment as run_environment
from mapbench.swarm import percentile

log = logging.getLogger(__name__)

DEFAULT_LOOKUPS = 1000
"""Lookups per ring: at N = 128 they take about a second, the ring's setup much longer."""

SWEEP = (8, 16, 32, 64, 128)
"""The ring sizes of `mapctl bench lookup --sweep`."""


def target_mean_hops(peers: int) -> float:
    """The mean hops we aim for on a ring of `peers` nodes: ½·log2 N + 1."""
    return 0.5 * math.log2(peers) + 1


def environment() -> dict[str, Any]:
    """The machine, Python and 1-minute load a plot's caption names: call it before
    the runs, whose own load would count otherwise."""
    return run_environment(use_uvloop=False, load=os.getloadavg()[0])


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
    started = time.perf_counter()
    async with still_ring(peers, rng, max_rounds=max_rounds) as nodes:
        setup = time.perf_counter() - started
        hops, millis, errors = await _time_lookups(nodes, lookups, rng)
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
