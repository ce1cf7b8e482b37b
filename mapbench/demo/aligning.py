"""The demo's align step: one peer places every mission in the world frame
(`mapctl align`) while every peer watches the `frames` table (`mapctl watch`)
and receives the places as they are committed (a place lies at its mission's
box in the world frame, where the watches listen)."""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

from mapbench.demo.errors import DemoFailed
from mapbench.demo.swarm import SwarmPeer

Json = Any
Progress = Any  # scenario.Progress: (kind, text) -> None

ALIGN_VIEW = "align"
FRAMES_WAIT_S = 30.0
"""How long a peer's watch may take to receive the places once aligned."""


async def align_missions(
    peers: Sequence[SwarmPeer], pattern: str, region: list[float], progress: Progress
) -> Json:
    """Every peer watches the places in `region` (of the world frame: where every
    robot starts, so every mission's box there overlaps it; a watch over the whole
    index is announced in every cell of it); the last peer aligns the missions
    matching `pattern`; every watch must receive a place for each. What it found.

    Raises:
        DemoFailed: a mission was left unaligned, or a watch missed a place.
    """
    aligner = peers[-1]
    watches = {
        p.name: (await p.call("watch_start", bbox=region, table="frames"))["watch"] for p in peers
    }
    done = await aligner.call("align", view=ALIGN_VIEW, missions=[pattern])
    before, after = done["rms_before"], done["rms_after"]
    progress(
        "info",
        f"{aligner.name} placed {len(done['frames'])} missions in the world frame of "
        f"{done['anchor']}: {done['inliers']} of {done['edges']} inter-robot edges kept, "
        f"their RMS {before['metres']:.1f} m -> {after['metres']:.2f} m",
    )
    if done["unaligned"]:
        raise DemoFailed(f"missions left unaligned: {', '.join(done['unaligned'])}")
    names = {f["mission"] for f in done["frames"]}
    seen = {}
    for peer in peers:
        seen[peer.name] = await _places_pushed(peer, watches[peer.name], names)
        progress("info", f"{peer.name}'s watch received the {len(names)} places")
    return {
        "peer": aligner.name,
        "anchor": done["anchor"],
        "missions": [f["mission"] for f in done["frames"]],
        "edges": done["edges"],
        "inliers": done["inliers"],
        "rms_before": before,
        "rms_after": after,
        "commit": done["commit"],
        "seen": seen,
    }


async def _places_pushed(peer: SwarmPeer, watch: str, names: set[str]) -> float:
    """Seconds until `peer`'s watch received a place for each of `names` (long
    polls of `watch_next`, within `FRAMES_WAIT_S`); the watch then stops.

    Raises:
        DemoFailed: it did not in time.
    """
    started, got = time.perf_counter(), set[str]()
    while not names <= got:
        left = FRAMES_WAIT_S - (time.perf_counter() - started)
        if left <= 0:
            raise DemoFailed(f"{peer.name}'s watch lacks the places of {sorted(names - got)}")
        pushed = await peer.call("watch_next", watch=watch, timeout=left)
        got |= {c["data"]["mission"] for c in pushed["changes"] if c["data"]}
    await peer.call("watch_stop", watch=watch)
    return round(time.perf_counter() - started, 3)
