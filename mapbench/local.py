"""`mapctl bench local`: single-peer figures on a fresh SQLite repository.

Measures commits/s for 1-item and 100-item transactions (inserts, then
updates of the same items), point reads/s at a past logical time, and the wall
time of starting `mapctl --help` and `mapctl get TABLE ID` as subprocesses.
Nothing here asserts a speed; the figures go to docs/benchmarks.md.
"""

from __future__ import annotations

import asyncio
import os
import platform
import random
import shutil
import sqlite3
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from mapapi.app import peer_of
from mapapi.core.ids import ChunkId, ItemId
from mapapi.core.table import message_class
from mapapi.service.peer import Peer
from mapapi.service.repo import Repository

TABLE = "bench"
TYPE = "mapapi.v1.Counter"
BATCH = 100  # items per transaction in the batch measurements
STARTUP_RUNS = 5


def run_local(commits: int, directory: str | Path | None = None) -> dict[str, Any]:
    """Measure a single peer on a fresh repository in a temporary folder.

    Args:
        commits: commits per measurement (1-item and 100-item transactions
            alike); point reads are 10 times as many.
        directory: where to create the temporary repository (default: the
            system's temporary folder); it is deleted afterwards.

    Returns:
        Flat JSON-ready figures: rates per second, startup times in seconds,
        the counts used, the Python and machine they were measured on, and the
        machine's 1-minute load average when the run started.
    """
    if commits < 1:
        raise ValueError(f"commits must be at least 1, got {commits}")
    load = os.getloadavg()[0]  # other work on the machine skews every figure
    with tempfile.TemporaryDirectory(prefix="mapapi-bench-", dir=directory) as tmp:
        repo = Repository.init(Path(tmp) / "repo", "bench")
        figures = asyncio.run(_measure_commits_and_reads(repo, commits))
        sample_id = figures.pop("_sample_id")
        figures["startup_help_s"] = _startup(["--help"], repo.root)
        figures["startup_get_s"] = _startup(["get", TABLE, sample_id], repo.root)
    return {
        **figures,
        "commits": commits,
        "items_per_commit_batch": BATCH,
        "startup_runs": STARTUP_RUNS,
        "python": platform.python_version(),
        "sqlite": sqlite3.sqlite_version,
        "machine": f"{platform.system()} {platform.machine()}, {os.cpu_count()} cpu",
        "load_1min_before": round(load, 2),
    }


async def _measure_commits_and_reads(repo: Repository, commits: int) -> dict[str, Any]:
    peer = peer_of(repo)  # the application's peer, with the map tables' rules
    try:
        await peer.create_table(TABLE, TYPE)
        chunk = await peer.create_chunk(TABLE)
        out: dict[str, Any] = {}

        single, seconds = await _insert(peer, chunk, commits, 1)
        out["commits_per_s_1_item"] = _rate(commits, seconds)
        seconds = await _update(peer, single, value=1)
        out["commits_per_s_1_item_update"] = _rate(commits, seconds)

        batches, seconds = await _insert(peer, chunk, commits, BATCH)
        out["commits_per_s_100_items"] = _rate(commits, seconds)
        out["items_per_s_100_items"] = _rate(commits * BATCH, seconds)
        past = peer.now()  # every batch item has value 0 here, 1 after the updates
        seconds = await _update(peer, batches, value=1)
        out["commits_per_s_100_items_update"] = _rate(commits, seconds)
        out["items_per_s_100_items_update"] = _rate(commits * BATCH, seconds)

        reads = 10 * commits
        ids = [i for batch in batches for i in batch]
        out["reads_per_s_past"] = _rate(reads, await _read_past(peer, ids, past, reads))
        out["reads"] = reads
        out["_sample_id"] = single[0][0]
        return out
    finally:
        await peer.close()


async def _insert(
    peer: Peer, chunk: ChunkId, commits: int, size: int
) -> tuple[list[list[ItemId]], float]:
    """`commits` transactions inserting `size` counters each; returns ids and seconds."""
    counter = message_class(TYPE)
    ids: list[list[ItemId]] = []
    start = time.perf_counter()
    for n in range(commits):
        tx = peer.begin()
        ids.append([tx.insert(TABLE, counter(name=f"c{n}.{k}"), chunk) for k in range(size)])
        await tx.commit("bench insert")
    return ids, time.perf_counter() - start


async def _update(peer: Peer, batches: list[list[ItemId]], value: int) -> float:
    """One transaction per batch setting every item's value; returns seconds."""
    counter = message_class(TYPE)
    start = time.perf_counter()
    for batch in batches:
        tx = peer.begin()
        for item_id in batch:
            tx.update(TABLE, item_id, counter(name="u", value=value))
        await tx.commit("bench update")
    return time.perf_counter() - start


async def _read_past(peer: Peer, ids: list[ItemId], at: int, reads: int) -> float:
    """`reads` point reads of random items at logical time `at`; returns seconds.

    Each read opens its own transaction at `at`, as a script or `mapctl get
    --at` does. The items were updated after `at`, so every read must find the
    older revision; a wrong value means the store is broken, not slow.
    """
    rng = random.Random(1)
    sample = [rng.choice(ids) for _ in range(reads)]
    start = time.perf_counter()
    for item_id in sample:
        message = await peer.begin(at=at).get(TABLE, item_id)
        if message is None or getattr(message, "value", None) != 0:
            raise RuntimeError(f"read of {item_id} at time {at} returned {message!r}")
    return time.perf_counter() - start


def _mapctl() -> list[str]:
    """How to start the CLI: the console script next to this Python, else `-m mapctl`."""
    script = Path(sys.executable).with_name("mapctl")
    if script.is_file():
        return [str(script)]
    found = shutil.which("mapctl")
    return [found] if found else [sys.executable, "-m", "mapctl"]


def _startup(args: list[str], cwd: Path) -> float:
    """Median wall time of `mapctl ARGS` over `STARTUP_RUNS` runs (after one warm-up)."""
    command = [*_mapctl(), *args]
    times = []
    for run in range(STARTUP_RUNS + 1):
        start = time.perf_counter()
        subprocess.run(command, cwd=cwd, check=True, capture_output=True)
        if run:  # the first run may compile bytecode or fill the page cache
            times.append(time.perf_counter() - start)
    return round(statistics.median(times), 4)


def _rate(count: int, seconds: float) -> float:
    return round(count / max(seconds, 1e-9), 1)  # finite, so --json stays valid JSON
