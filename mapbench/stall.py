"""Does a busy peer keep its pace? (issue 14 §1)

    python -m mapbench.stall                      # 100,000 items, JSON on stdout
    python -m mapbench.stall --items 20000 --load-items 5000

Two peer daemons on 127.0.0.1, each a `mapctl peer start --detach` process in
a fresh repository under a temporary folder. Peer A holds a generated 2D pose
graph of `items` rows (half vertices, half edges: a random walk, the odometry
between neighbours and one loop closure); peer B holds one of `load_items`
rows far away and a small one near A's. A first loads the small one
(`query-bbox --load`), so each holds a chunk of the other's and their failure
detectors watch each other. Then three `mapctl` processes run at once against
A: `export` of its big mission to g2o, `plot` of it, and `query-bbox --load`
of B's far mission (a chunk transfer of `load_items` rows into A). Meanwhile
A's `peer status --json` is asked every `poll` seconds: how late A's event
loop ran (`loop_lag_ms`: p50, p99, max over the last minute, which covers the
whole run) and how long the answer took. Afterwards both `peer.log`s are read
for suspicions ("peer ... is suspect" or "is dead").

The report (JSON): the items, each command's seconds (and why any failed),
every status poll, A's and B's final lag, the worst p99 and max A reported,
the slowest status answer and how many went unanswered (the CLI gives up
after its timeout), the suspicions, the machine's load average before
and after, and the share of CPU time its hypervisor stole meanwhile
(`cpu_steal_percent`, from `/proc/stat`). Nothing is asserted here;
tests/multiproc/test_loop_lag.py asserts on the same run, and the figures go
to docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import random
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from mapapi.service.daemon_process import stop_daemon
from mapapi.service.repo import Repository

COMMAND_TIMEOUT = 180.0
"""Seconds one `mapctl` command may take (an import of 100,000 rows on a loaded machine)."""

SUSPICION = re.compile(r"peer \w+ is (suspect|dead) \(was")
"""A line of `peer.log` in which the failure detector suspects a peer (`swarm/liveness.py`)."""

_SIDE = 150.0  # metres: a walk stays within a square of twice this around its origin
FAR = (600.0, 600.0)  # where B's mission to load lies
NEAR = (-600.0, -600.0)  # where B's small mission lies


def write_walk(path: Path, poses: int, origin: tuple[float, float], seed: int = 1) -> None:
    """Write a 2D g2o pose graph of `poses` vertices and `poses` edges: a random
    walk of 0.5 m steps about `origin`, odometry between neighbours and one loop
    closure from the last pose to the first."""
    rng = random.Random(seed)
    x, y, theta = origin[0], origin[1], 0.0
    info = "500 0 0 500 0 2000"
    with path.open("w", encoding="utf-8") as out:
        for i in range(poses):
            out.write(f"VERTEX_SE2 {i} {x:.4f} {y:.4f} {theta:.4f}\n")
            theta += rng.uniform(-0.3, 0.3)
            x = min(max(x + 0.5 * math.cos(theta), origin[0] - _SIDE), origin[0] + _SIDE)
            y = min(max(y + 0.5 * math.sin(theta), origin[1] - _SIDE), origin[1] + _SIDE)
        for i in range(poses - 1):
            out.write(f"EDGE_SE2 {i} {i + 1} 0.5 0 {rng.uniform(-0.3, 0.3):.4f} {info}\n")
        out.write(f"EDGE_SE2 {poses - 1} 0 0 0 0 {info}\n")


def _box(origin: tuple[float, float]) -> list[str]:
    """The `query-bbox` arguments of a box around a walk about `origin`."""
    m = _SIDE + 10.0
    x, y = origin
    return ["--", *(str(v) for v in (x - m, y - m, -10.0, x + m, y + m, 10.0))]


def _command(repo: Path, *args: str) -> list[str]:
    return [sys.executable, "-m", "mapctl", "-C", str(repo), *args]


def mapctl(repo: Path, *args: str) -> str:
    """Run `mapctl -C repo ARGS`; its stdout.

    Raises:
        RuntimeError: it failed (its stderr says why).
    """
    done = subprocess.run(
        _command(repo, *args), capture_output=True, text=True, timeout=COMMAND_TIMEOUT, check=False
    )
    if done.returncode != 0:
        raise RuntimeError(f"mapctl {' '.join(args[:3])} exited {done.returncode}: {done.stderr}")
    return done.stdout


def _status(repo: Path) -> tuple[dict[str, Any] | str, float]:
    """`peer status --json` of `repo` (or why the CLI gave up on it: a peer that
    did not answer in time), and the seconds it took."""
    started = time.perf_counter()
    try:
        status: dict[str, Any] | str = json.loads(mapctl(repo, "peer", "status", "--json"))
    except RuntimeError as exc:
        status = str(exc).strip().splitlines()[-1]
    if isinstance(status, dict) and not status.get("running"):
        status = "the peer does not run"
    return status, round(time.perf_counter() - started, 3)


def _suspicions(repo: Path) -> list[str]:
    log = repo / ".mapapi" / "peer.log"
    text = log.read_text(encoding="utf-8", errors="replace") if log.exists() else ""
    return [line for line in text.splitlines() if SUSPICION.search(line)]


def _setup(root: Path, items: int, load_items: int) -> tuple[Path, Path]:
    """Repositories a (with the big mission) and b (the far and the near ones),
    imported offline, then both daemons started, a joined to b, and a holding
    the near mission."""
    a, b = root / "a", root / "b"
    write_walk(root / "big.g2o", items // 2, (0.0, 0.0))
    write_walk(root / "far.g2o", load_items // 2, FAR, seed=2)
    write_walk(root / "near.g2o", 100, NEAR, seed=3)
    for repo in (a, b):
        subprocess.run(
            [sys.executable, "-m", "mapctl", "init", str(repo), "--name", repo.name],
            check=True,
            capture_output=True,
            timeout=COMMAND_TIMEOUT,
        )
    mapctl(a, "import", str(root / "big.g2o"))
    mapctl(b, "import", str(root / "far.g2o"))
    mapctl(b, "import", str(root / "near.g2o"))
    join = json.loads(mapctl(b, "peer", "start", "--detach", "--json"))["join"]
    mapctl(a, "peer", "start", "--detach", "--json", "--join", join)
    mapctl(a, "query-bbox", "--load", *_box(NEAR))
    return a, b


def _workload(
    root: Path, a: Path, poll: float
) -> tuple[dict[str, float], dict[str, str], list[dict[str, Any]]]:
    """Export, plot and load at once against `a`, asking its status every `poll`
    seconds; each command's seconds, the commands that failed (and why), the polls."""
    commands = {
        "export": ("export", "big", "-o", str(root / "big-out.g2o")),
        "plot": ("plot", "--mission", "big", "-o", str(root / "big.png")),
        "load": ("query-bbox", "--load", *_box(FAR)),
    }
    started = time.perf_counter()
    running = {
        name: subprocess.Popen(
            _command(a, *args), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True
        )
        for name, args in commands.items()
    }
    seconds: dict[str, float] = {}
    failed: dict[str, str] = {}
    polls: list[dict[str, Any]] = []
    deadline = started + COMMAND_TIMEOUT
    try:
        while running:
            process = next(iter(running.values()))
            with contextlib.suppress(subprocess.TimeoutExpired):
                process.wait(timeout=poll)  # paces the polls; returns early once it ends
            for done in [n for n, p in running.items() if p.poll() is not None]:
                ended = running.pop(done)
                seconds[done] = round(time.perf_counter() - started, 2)
                why = ended.communicate()[1].strip()  # reads and closes its pipe
                if ended.returncode != 0:
                    failed[done] = f"exit {ended.returncode}: {why}"
            status, took = _status(a)
            polls.append(
                {
                    "at": round(time.perf_counter() - started, 2),
                    "answer_s": took,
                    "loop_lag_ms": _lag(status),
                    **({"error": status} if isinstance(status, str) else {}),
                }
            )
            if time.perf_counter() > deadline:
                raise RuntimeError(f"{', '.join(running)} still ran after {COMMAND_TIMEOUT} s")
    finally:
        for process in running.values():
            process.kill()
            process.communicate()
    return seconds, failed, polls


def measure_stall(
    items: int = 100_000, load_items: int = 20_000, poll: float = 0.5, root: Path | None = None
) -> dict[str, Any]:
    """Run the benchmark (see the module docstring) in `root` (a new temporary
    folder by default, removed afterwards); the report."""
    if root is None:
        with tempfile.TemporaryDirectory(prefix="mapbench-stall-") as scratch:
            return measure_stall(items, load_items, poll, Path(scratch))
    load_before, cpu_before = os.getloadavg(), _cpu_times()
    a, b = root / "a", root / "b"
    try:
        a, b = _setup(root, items, load_items)
        seconds, failed, polls = _workload(root, a, poll)
        final_a, _ = _status(a)
        final_b, _ = _status(b)
    finally:
        for repo in (a, b):
            if (repo / ".mapapi").is_dir() and Repository.find(repo).running_peer():
                stop_daemon(Repository.find(repo), timeout=30.0)
    lags = [p["loop_lag_ms"] for p in polls] + [_lag(final_a)]
    answered = [lag for lag in lags if lag is not None]
    return {
        "items": items,
        "load_items": load_items,
        "seconds": seconds,
        "failed": failed,
        "polls": polls,
        "loop_lag_ms": _lag(final_a),
        "loop_lag_ms_b": _lag(final_b),
        "worst_p99_ms": max((lag["p99"] for lag in answered), default=None),
        "worst_max_ms": max((lag["max"] for lag in answered), default=None),
        "unanswered": len(lags) - len(answered),
        "slowest_status_s": max(p["answer_s"] for p in polls),
        "suspicions": _suspicions(a) + _suspicions(b),
        "load_average": [round(load_before[0], 2), round(os.getloadavg()[0], 2)],
        "cpu_steal_percent": _steal_percent(cpu_before, _cpu_times()),
    }


def _cpu_times() -> list[int] | None:
    """The machine's CPU times so far (`/proc/stat`'s first line, in ticks), None
    where there is no such file."""
    try:
        with open("/proc/stat", encoding="ascii") as stat:
            return [int(v) for v in stat.readline().split()[1:9]]
    except (OSError, ValueError):
        return None


def _steal_percent(before: list[int] | None, after: list[int] | None) -> float | None:
    """The share of CPU time the hypervisor gave to other machines between two
    readings (`steal`, the eighth field): the cores this run could not have."""
    if before is None or after is None or sum(after) == sum(before):
        return None
    return round(100 * (after[7] - before[7]) / (sum(after) - sum(before)), 1)


def _lag(status: dict[str, Any] | str) -> dict[str, float] | None:
    return None if isinstance(status, str) else dict(status["loop_lag_ms"])


def main(argv: list[str] | None = None) -> None:
    """`python -m mapbench.stall`: run it, print the report as JSON."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--items", type=int, default=100_000, help="rows of A's mission")
    parser.add_argument("--load-items", type=int, default=20_000, help="rows A loads from B")
    parser.add_argument("--poll", type=float, default=0.5, help="seconds between status polls")
    args = parser.parse_args(argv)
    print(json.dumps(measure_stall(args.items, args.load_items, args.poll)))


if __name__ == "__main__":
    main()
