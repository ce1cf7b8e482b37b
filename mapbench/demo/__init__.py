"""`mapctl demo`: a local swarm of peer processes builds one map (issue 5 §5).

`run_demo` makes a temporary folder, runs the steps of `mapbench.demo.scenario`
over a `LocalSwarm` of daemons in it, stops every daemon it started (also on
Ctrl-C, SIGTERM or an error) and removes the folder, except after a failure,
when the peers' logs are worth a look. The summary it returns is what `mapctl
demo --json` prints (docs/guide/demo.md lists its keys).
"""

from __future__ import annotations

import asyncio
import contextlib
import shutil
import signal
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from types import FrameType
from typing import Any

from mapapi.core.errors import MapError, UsageError
from mapbench.demo.scenario import Demo, DemoFailed, Progress
from mapbench.demo.swarm import LocalSwarm

Json = Any

PEER_NAMES = ("alpha", "bravo", "charlie", "delta")
TUNNELS = Path(__file__).resolve().parents[2] / "sample_maps" / "kimera_multi_tunnels_8robots"


def run_demo(
    out: Path, peers: int = 4, progress: Progress | None = None, tunnels: Path = TUNNELS
) -> Json:
    """Run the demo with `peers` peer processes; PNGs go to `out` (created).

    Returns:
        The summary (see docs/guide/demo.md), with the time the stop took.

    Raises:
        UsageError: `peers` is not 3 or 4, `out` is a file, or the tunnels set is missing.
        DemoFailed: the swarm did not do what the demo shows.
        MapError: a peer failed (the temporary folder is kept for its log).
    """
    if not 3 <= peers <= len(PEER_NAMES):
        raise UsageError(f"the demo runs 3 or 4 peers, not {peers}")
    if not tunnels.is_dir():
        raise UsageError(
            f"the demo needs the tunnels set at {tunnels}; run it from a source tree "
            "(git clone, then `make demo`)"
        )
    if out.exists() and not out.is_dir():
        raise UsageError(f"{out} is a file; pass --out a folder")
    out.mkdir(parents=True, exist_ok=True)
    tell = progress or (lambda kind, text: None)
    started = time.perf_counter()
    root = Path(tempfile.mkdtemp(prefix="mapapi-demo-"))
    keep = False
    swarm: LocalSwarm | None = None
    try:
        tell("info", f"the swarm runs in {root}")
        swarm = LocalSwarm(root, PEER_NAMES[:peers])
        demo = Demo(swarm, tunnels, out.resolve(), tell)
        with _sigterm_interrupts():
            summary: Json = asyncio.run(demo.run())
    except MapError:
        keep = True
        raise
    finally:
        stopping = time.perf_counter()
        stopped = swarm.stop() if swarm is not None else []
        tell("info", f"stopped {len(stopped)} peer processes")
        if keep:
            tell("info", f"kept {root} for the peers' logs (.mapapi/peer.log)")
        else:
            shutil.rmtree(root, ignore_errors=True)
    summary["timings"]["stop"] = round(time.perf_counter() - stopping, 3)
    summary["timings"]["total"] = round(time.perf_counter() - started, 3)
    summary["out"] = str(out.resolve())
    summary["swarm"] = str(root)  # removed by now
    return summary


@contextlib.contextmanager
def _sigterm_interrupts() -> Iterator[None]:
    """Turn SIGTERM into KeyboardInterrupt meanwhile, so the cleanup runs as on Ctrl-C."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def interrupt(signum: int, frame: FrameType | None) -> None:
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, interrupt)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


__all__ = ["PEER_NAMES", "DemoFailed", "run_demo"]
