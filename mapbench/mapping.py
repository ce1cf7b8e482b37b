"""`mapctl bench mapping`: the workload robots produce, through the chunks' Raft
groups (DESIGN §13).

P robots, each a `python -m mapbench.worker` peer process on loopback (the
machinery of `mapbench.workers`, as `bench viewtest`). Each robot writes its own
mission into the map tables (`mapapi.maps.schema`): a chunk of the `vertices`
table and one of `edges`, each held by K peers (the robot and the K-1 next
ones, round the ring of robots), so each is a Raft group of K members. The
robots then stream for S seconds at once, each on its own
(`mapbench.robot`): commits of 10-100 vertices, then of their edges. 5 % of
the edges are inter-robot edges, each written into the robot's edge chunk and,
as a copy, into the other robot's: the edge commit then writes several chunks
(a two-phase commit across their groups); with `alone`, each inter-robot edge
is a two-chunk commit of its own instead. A peer writes only chunks it holds,
so a robot's inter-robot edges go to the K-1 robots whose chunks it holds
(with K = 1 there are none).

Afterwards every holder's replica of every chunk, caught up with the chunk's
leader, must hold exactly the items the writers had acknowledged
(`check_mapping`). Nothing here asserts a speed; the figures go to
docs/benchmarks.md.
"""

from __future__ import annotations

import functools
import os
import statistics
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mapbench.robot import Digest
from mapbench.swarm import (
    diff,
    environment,
    expect_holders,
    join_swarm,
    percentile,
    scratch,
    traffic,
)
from mapbench.workers import SwarmCheckFailed, WorkerProcess, spawn_workers

SEED_VERTICES = 20
"""Vertices each robot commits before the run: the ends of inter-robot edges."""
STREAM_GRACE = 120.0
"""Seconds a robot may take past its S seconds to report (its last commit, a
slow machine)."""


@dataclass(frozen=True, slots=True)
class Workload:
    """What each robot writes.

    Attributes:
        seconds: how long every robot streams.
        batch: the smallest and largest number of vertices of one commit (its
            odometry edges follow in the next).
        cross: the share of edges that end at another robot's vertex.
        alone: commit each such edge on its own (else with the robot's other
            edges of the round, which then makes that commit multi-chunk).
        seed: seeds robot i's choices with seed + i.
    """

    seconds: float = 10.0
    batch: tuple[int, int] = (10, 100)
    cross: float = 0.05
    alone: bool = False
    seed: int = 0


def mapping(
    robots: int,
    holders: int,
    workload: Workload = Workload(),
    *,
    directory: str | Path | None = None,
    use_uvloop: bool = False,
) -> dict[str, Any]:
    """Run the mapping workload (module docstring) and gather its figures.

    Args:
        robots: P, robot peer processes.
        holders: K, holders of each chunk (1 <= K <= P).
        workload: what each robot writes, and for how long.
        directory: where the scratch repositories go (default: the temp folder).
        use_uvloop: run every peer's event loop on uvloop.

    Returns:
        JSON-ready figures: items_per_s (every item acknowledged during the
        runs over the wall time), commit p50/p99 ms, bytes and messages sent
        per item (every process, requests and replies), commits, multi-chunk
        commits, retries by kind, CPU; then `chunks`: per chunk, the digest the
        writers acknowledged and each holder's (see `check_mapping`).
    """
    if not 1 <= holders <= robots:
        raise ValueError(f"holders must be between 1 and robots ({robots}), got {holders}")
    low, high = workload.batch
    if not 1 <= low <= high:
        raise ValueError(f"the batch range must be 1 <= low <= high, got {low}..{high}")
    load = os.getloadavg()[0]
    spawn = functools.partial(spawn_workers, use_uvloop=use_uvloop)
    with scratch(directory) as tmp, spawn(robots, Path(tmp)) as ws:
        made = _place_chunks(ws, holders)
        for worker in ws:
            worker.call("seeded", "seed", SEED_VERTICES)
        before = traffic(ws)
        reports, seconds = _stream(ws, made, holders, workload)
        after = traffic(ws)
        held = [w.call("digest", "digest")["chunks"] for w in ws]
    items = sum(r["items"] for r in reports)
    single = [x for r in reports for x in r["single_ms"]]
    multi = [x for r in reports for x in r["multi_ms"]]
    retries: dict[str, int] = {}
    for report in reports:
        for kind, count in report["retries"].items():
            retries[kind] = retries.get(kind, 0) + count
    return {
        "robots": robots,
        "holders": holders,
        "seconds": round(seconds, 3),
        "items": items,
        "items_per_s": round(items / seconds, 1),
        **_halves(reports, workload.seconds),
        "commits": len(single) + len(multi),
        "multi_chunk_commits": len(multi),
        **_latency("commit", single + multi),
        **_latency("single_chunk", single),
        **_latency("multi_chunk", multi),
        "bytes_per_item": round((after.bytes - before.bytes) / max(items, 1), 1),
        "messages_per_item": round((after.messages - before.messages) / max(items, 1), 3),
        "conflicts": retries.get("conflict", 0),
        "retries": sum(retries.values()),
        "retries_by_kind": retries,
        "cpu_ms_per_item": round((after.cpu_s - before.cpu_s) * 1e3 / max(items, 1), 4),
        "peer_cores_used": round((after.cpu_s - before.cpu_s) / seconds, 2),
        "robot_items_per_s": [round(r["items"] / r["seconds"], 1) for r in reports],
        "messages_by_type": diff(after.by_type, before.by_type),
        "batch": [low, high],
        "cross": workload.cross,
        "cross_alone": workload.alone,
        "chunks": _chunk_digests(ws, made, holders, reports, held),
        **environment(use_uvloop, load),
    }


def _halves(reports: Sequence[dict[str, Any]], seconds: float) -> dict[str, float]:
    """Items/s of every robot together in the first and the second half of the
    time: whether the rate holds as the chunks grow."""
    first = sum(r["items_first_half"] for r in reports)
    rest = sum(r["items"] for r in reports) - first
    late = max(statistics.fmean(r["seconds"] for r in reports) - seconds / 2, 1e-9)
    return {
        "items_per_s_first_half": round(first / (seconds / 2), 1),
        "items_per_s_second_half": round(rest / late, 1),
    }


def _latency(name: str, values: Sequence[float]) -> dict[str, float | None]:
    """`name`_p50_ms and `name`_p99_ms of `values` (None without any)."""
    return {
        f"{name}_{q}_ms": round(percentile(values, f), 3) if values else None
        for q, f in (("p50", 0.5), ("p99", 0.99))
    }


def _place_chunks(ws: Sequence[WorkerProcess], holders: int) -> list[dict[str, str]]:
    """Join the swarm; each robot makes its chunks, the K-1 next robots hold them."""
    join_swarm(ws)
    made = [w.call("robot", "robot", i) for i, w in enumerate(ws)]
    for i, chunks in enumerate(made):
        group = [ws[(i + j) % len(ws)] for j in range(holders)]
        for chunk in (chunks["vertices"], chunks["edges"]):
            for worker in group[1:]:
                worker.call("participating", "participate", chunk)
            expect_holders(group, chunk, holders)
    return made


def _stream(
    ws: Sequence[WorkerProcess],
    made: Sequence[dict[str, str]],
    holders: int,
    workload: Workload,
) -> tuple[list[dict[str, Any]], float]:
    """Start every robot's stream at once; their reports and the wall time.

    A transaction writes only chunks held where it runs, so robot i's
    inter-robot edges go to the K-1 robots before it, whose chunks it holds."""
    low, high = workload.batch
    started = time.perf_counter()
    for i, worker in enumerate(ws):
        held = [made[(i - j) % len(ws)] for j in range(1, holders)]
        others = [f"{m['mission']}={m['edges']}" for m in held]
        alone = int(workload.alone)
        args = (workload.seconds, low, high, workload.cross, alone, workload.seed + i, *others)
        worker.send("stream", *args)
    reports = [w.reply("streamed", workload.seconds + STREAM_GRACE) for w in ws]
    return reports, time.perf_counter() - started


def _chunk_digests(
    ws: Sequence[WorkerProcess],
    made: Sequence[dict[str, str]],
    holders: int,
    reports: Sequence[dict[str, Any]],
    held: Sequence[dict[str, list[int]]],
) -> dict[str, dict[str, Any]]:
    """Per chunk: the writers' acknowledged digest summed, and each holder's."""
    acked: dict[str, Digest] = {}
    for report in reports:
        for chunk, pair in report["acked"].items():
            acked.setdefault(chunk, Digest()).merge(pair)
    out: dict[str, dict[str, Any]] = {}
    for i, chunks in enumerate(made):
        group = [(i + j) % len(ws) for j in range(holders)]
        for chunk in (chunks["vertices"], chunks["edges"]):
            out[chunk] = {
                "acked": acked.get(chunk, Digest()).pair(),
                "holders": {ws[h].name: held[h].get(chunk) for h in group},
            }
    return out


def check_mapping(result: dict[str, Any]) -> None:
    """Raise `SwarmCheckFailed` unless every holder of every chunk holds exactly
    the items its writers acknowledged (same count, same sum of item hashes).

    Raises:
        SwarmCheckFailed: naming the chunk, the holder and both digests.
    """
    for chunk, seen in result["chunks"].items():
        for holder, digest in seen["holders"].items():
            if digest != seen["acked"]:
                raise SwarmCheckFailed(
                    f"{holder} holds {digest} (items, hash) of chunk {chunk}, but its "
                    f"writers acknowledged {seen['acked']}"
                )
