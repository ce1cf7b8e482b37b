"""Swarm benchmarks over peer processes: `mapctl bench viewtest` and `bench commit`.

Each peer is a `python -m mapbench.worker` child on loopback, driven over
its acknowledged line protocol (see `mapbench.worker`); every reply is
awaited under a deadline and every child is stopped (then killed) on the way
out. Nothing here asserts a speed; the figures go to docs/benchmarks.md.

- `viewtest` (paper Algorithm 1, DESIGN §12): P peers hold one counter chunk
  and all increment the one counter N times at once, retrying on conflict;
  afterwards every peer must read a0 + P*N and hold the same commit log.
- `commit_latency`: one writer commits N increments, uncontended, to a chunk
  held by K peer processes (the writer is one of them).
"""

from __future__ import annotations

import functools
import os
import platform
import statistics
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from mapbench.workers import (
    SwarmCheckFailed,
    WorkerProcess,
    spawn_workers,
)

RUN_DEADLINE = 300.0
Writer = Literal["leader", "follower"]


def join_swarm(workers: Sequence[WorkerProcess]) -> None:
    """Join every worker to the swarm through the first."""
    for worker in workers[1:]:
        worker.call("joined", "join", workers[0].address)


def expect_holders(workers: Sequence[WorkerProcess], chunk: str, count: int) -> None:
    """Check that each of `workers` knows `count` holders of `chunk`.

    Raises:
        SwarmCheckFailed: naming the worker and what it knows.
    """
    for worker in workers:
        holders = worker.call("holders", "holders", chunk)["holders"]
        if len(holders) != count:
            raise SwarmCheckFailed(
                f"{worker.name} knows {len(holders)} holders of chunk {chunk}, expected {count}"
            )


def counter_swarm(workers: Sequence[WorkerProcess], a0: int = 0) -> tuple[str, str]:
    """Join every worker through the first, create the counter chunk on the first
    and make every other worker participate; returns (chunk id, item id)."""
    join_swarm(workers)
    created = workers[0].call("created", "create", a0)
    for worker in workers[1:]:
        worker.call("participating", "participate", created["chunk"])
    expect_holders(workers, created["chunk"], len(workers))
    return created["chunk"], created["item"]


def run_increments(
    workers: Sequence[WorkerProcess], n: int, item: str, deadline: float = RUN_DEADLINE
) -> tuple[list[dict[str, Any]], float]:
    """Start Algorithm 1 (`run`) on every worker at once; returns their reports
    and the wall time from the first command sent to the last report read."""
    start = time.perf_counter()
    for worker in workers:
        worker.send("run", n, item, deadline)
    reports = [w.reply("ran", deadline + 10.0) for w in workers]
    return reports, time.perf_counter() - start


@dataclass(frozen=True, slots=True)
class Traffic:
    """What every worker sent so far, summed: messages (in all and by type),
    bytes, and CPU seconds used."""

    messages: int
    bytes: int
    by_type: dict[str, int]
    cpu_s: float


def traffic(workers: Sequence[WorkerProcess]) -> Traffic:
    """The workers' traffic and CPU counters now, summed (`stats`)."""
    total, size, cpu = 0, 0, 0.0
    by_type: dict[str, int] = {}
    for worker in workers:
        stats = worker.call("stats", "stats")
        total += stats["sent"]
        size += stats["sent_bytes"]
        cpu += stats["cpu_s"]
        for name, count in stats["sent_by_type"].items():
            by_type[name] = by_type.get(name, 0) + count
    return Traffic(total, size, by_type, cpu)


def diff(after: dict[str, int], before: dict[str, int]) -> dict[str, int]:
    """The counts that grew from `before` to `after`, by how much."""
    return {k: v - before.get(k, 0) for k, v in sorted(after.items()) if v - before.get(k, 0)}


def percentile(values: Sequence[float], q: float) -> float:
    """The `q`-quantile (0..1) of `values`, nearest rank."""
    ordered = sorted(values)
    if not ordered:
        raise ValueError("no samples")
    return ordered[min(len(ordered) - 1, int(len(ordered) * q))]


def environment(use_uvloop: bool, load: float, secure: bool = False) -> dict[str, Any]:
    """What a figure was measured on: loop, Python, machine, load before the run."""
    return {
        "secure": secure,
        "loop": "uvloop" if use_uvloop else "asyncio",
        "python": platform.python_version(),
        "machine": f"{platform.system()} {platform.machine()}, {os.cpu_count()} cpu",
        "load_1min_before": round(load, 2),
    }


def scratch(directory: str | Path | None) -> tempfile.TemporaryDirectory[str]:
    """A scratch folder for the workers' repositories (in `directory` if given)."""
    return tempfile.TemporaryDirectory(prefix="mapapi-swarm-", dir=directory)


def viewtest(
    peers: int,
    n: int,
    *,
    a0: int = 0,
    directory: str | Path | None = None,
    use_uvloop: bool = False,
    deadline: float = RUN_DEADLINE,
    secure: bool = False,
) -> dict[str, Any]:
    """Paper Algorithm 1 across `peers` processes, `n` increments each (`secure`:
    a secure swarm, CurveZMQ between the peers).

    Returns:
        JSON-ready figures: peers, n, expected (a0 + peers*n), final (the value
        if every peer reads the same, else None), commits_per_s, aborts_per_commit,
        p50_ms and p99_ms of one increment (first begin to successful commit,
        retries included), then details: every peer's value and log length,
        whether the logs are identical, messages per commit, the environment.
        Call `check_viewtest` on it to turn a disagreement into an error.
    """
    if peers < 1 or n < 1:
        raise ValueError(f"peers and n must be at least 1, got {peers} and {n}")
    load = os.getloadavg()[0]
    spawn = functools.partial(spawn_workers, use_uvloop=use_uvloop, secure=secure)
    with scratch(directory) as tmp, spawn(peers, Path(tmp)) as ws:
        _, item = counter_swarm(ws, a0)
        before = traffic(ws)
        reports, seconds = run_increments(ws, n, item, deadline)
        after = traffic(ws)
        values = [w.call("value", "value", item) for w in ws]
        logs = [w.call("log", "log")["ids"] for w in ws]
    commits = peers * n
    increments = [x for r in reports for x in r["increment_ms"]]
    commit_calls = [x for r in reports for x in r["commit_ms"]]
    distinct = {v["value"] for v in values}
    return {
        "peers": peers,
        "n": n,
        "expected": a0 + commits,
        "final": distinct.pop() if len(distinct) == 1 else None,
        "commits_per_s": round(commits / seconds, 1),
        "aborts_per_commit": round(sum(r["aborts"] for r in reports) / commits, 3),
        "p50_ms": round(percentile(increments, 0.5), 3),
        "p99_ms": round(percentile(increments, 0.99), 3),
        "commit_p50_ms": round(percentile(commit_calls, 0.5), 3),
        "commit_p99_ms": round(percentile(commit_calls, 0.99), 3),
        "values": [v["value"] for v in values],
        "log_lengths": [v["log"] for v in values],
        "logs_identical": all(lg == logs[0] for lg in logs),
        "conflicts": sum(r["conflicts"] for r in reports),
        "lock_timeouts": sum(r["lock_timeouts"] for r in reports),
        "other_retries": sum(r["other_retries"] for r in reports),
        "messages_per_commit": round((after.messages - before.messages) / commits, 2),
        "messages_by_type": diff(after.by_type, before.by_type),
        "cpu_ms_per_commit": round((after.cpu_s - before.cpu_s) * 1e3 / commits, 3),
        "seconds": round(seconds, 3),
        "a0": a0,
        **environment(use_uvloop, load, secure),
    }


def check_viewtest(result: dict[str, Any]) -> None:
    """Raise `SwarmCheckFailed` unless every peer reads a0 + P*N and holds one log.

    Raises:
        SwarmCheckFailed: naming what differs.
    """
    if result["final"] is None:
        raise SwarmCheckFailed(
            f"the peers disagree on the counter: {result['values']} (expected "
            f"{result['expected']} on every peer)"
        )
    if result["final"] != result["expected"]:
        raise SwarmCheckFailed(
            f"every peer reads {result['final']}, expected {result['expected']}: "
            f"{result['expected'] - result['final']} increment(s) lost"
        )
    if not result["logs_identical"]:
        raise SwarmCheckFailed(f"the peers' commit logs differ (lengths {result['log_lengths']})")


def commit_latency(
    holders: int,
    n: int,
    *,
    writer: Writer = "follower",
    directory: str | Path | None = None,
    use_uvloop: bool = False,
    warmup: int = 50,
    secure: bool = False,
) -> dict[str, Any]:
    """Uncontended commits by one writer to a chunk held by `holders` processes.

    Args:
        holders: peer processes holding the chunk (the writer is one of them).
        n: timed commits (one Algorithm 1 increment each, never a conflict).
        writer: "follower" commits from a holder that does not lead the chunk's
            group, which forwards to the leader (one more round trip); "leader"
            from the leader itself (the peer that created the chunk). With one
            holder both are the same.
        warmup: untimed commits first (connections, caches).
        secure: a secure swarm (CurveZMQ between the peers).

    Returns:
        JSON-ready figures: holders, n, p50_ms / p99_ms / mean_ms of `commit()`,
        messages per commit summed over every process (requests and replies,
        by type), and the environment.
    """
    if holders < 1 or n < 1:
        raise ValueError(f"holders and n must be at least 1, got {holders} and {n}")
    load = os.getloadavg()[0]
    spawn = functools.partial(spawn_workers, use_uvloop=use_uvloop, secure=secure)
    with scratch(directory) as tmp, spawn(holders, Path(tmp)) as ws:
        _, item = counter_swarm(ws)
        chosen = ws[0] if writer == "leader" else ws[-1]  # ws[0] made the chunk: it leads
        if warmup:
            run_increments([chosen], warmup, item)
        before = traffic(ws)
        (report,), _ = run_increments([chosen], n, item)
        after = traffic(ws)
        values = {w.call("value", "value", item)["value"] for w in ws}
    if values != {warmup + n}:
        raise SwarmCheckFailed(f"holders read {sorted(values)}, expected {warmup + n}")
    latencies = report["commit_ms"]
    return {
        "holders": holders,
        "n": n,
        "writer": "leader" if chosen is ws[0] else "follower",
        "p50_ms": round(percentile(latencies, 0.5), 3),
        "p99_ms": round(percentile(latencies, 0.99), 3),
        "mean_ms": round(statistics.fmean(latencies), 3),
        "commits_per_s": round(n / report["seconds"], 1),
        "messages_per_commit": round((after.messages - before.messages) / n, 2),
        "messages_by_type": diff(after.by_type, before.by_type),
        "cpu_ms_per_commit": round((after.cpu_s - before.cpu_s) * 1e3 / n, 3),
        "aborts": report["aborts"],
        **environment(use_uvloop, load, secure),
    }
