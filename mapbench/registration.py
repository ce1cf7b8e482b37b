"""`mapctl bench registration`: registering aerial missions against ground
missions, decentralized or centralized, under limited bandwidth (the Map API
paper, Cieslewski et al., ICRA 2015, Fig. 7; issue 5 §6).

The data are the 8 robots of the tunnels set (`sample_maps/`), one mission
each, every one in its own frame. It holds no aerial robot, so roles are
assigned: the first `ground` robots are the ground robots, the last `aerial`
ones play the aerial robots whose missions arrive to be registered (by
default robots 4-7: the longest trajectories, the ones covering the most
ground). A ground robot knows which aerial missions are near it from its own
inter-robot edges (`linked_missions`): they name the aerial vertices it saw
again. Its registration job is `register_missions(its mission, those aerial
missions)` (gtsam, `mapapi.maps.registration`).

Each robot is a peer holding its own mission (imported before the clock
starts). Both modes run the same jobs on a fresh swarm of real peers in this
process (loopback sockets, port 0), with every link shaped
(`mapapi.net.shaping`: one message at a time per link and direction):

- ``decentralized``: every ground peer fetches the aerial missions near it
  over 1 MB/s links and runs its own job;
- ``centralized``: one more peer, the server, fetches every mission over
  100 kB/s links and runs every job.

A fetch is `Peer.participate` in each of the mission's chunks (missions,
vertices, edges) in turn, by the ids that `mapctl missions --json` on the
holder names: the holders are looked up in the Chord ring and each chunk
travels whole, with its history, as `query-bbox --load` fetches it.

Per fetching peer: bytes received and seconds fetching (transfer), then
seconds reading the missions from its store and registering them (compute).
In the field the ground robots work at once, each on its own CPU and radio;
in one process they would share one CPU, so they are measured one after the
other (a later one may fetch a chunk from an earlier one, which holds it
now), and the jobs run once the swarm has closed (gtsam holds the GIL, which
would stall every peer's event loop). A decentralized run's wall time is
therefore its slowest peer's transfer plus compute. Both modes must compute
equal frames (`check_registration`). Nothing here asserts a time; the
figures go to docs/benchmarks.md.
"""

from __future__ import annotations

import asyncio
import logging
import math
import random
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mapapi.core.errors import MapError, UsageError
from mapapi.core.ids import ChunkId
from mapapi.lookup.spatial import SpatialGrid
from mapapi.maps.alignment import invert, pose_matrix, residuals
from mapapi.maps.graph import MissionGraph
from mapapi.maps.importer import import_missions
from mapapi.maps.kimera import read_kimera
from mapapi.maps.registration import (
    Registration,
    linked_missions,
    register_missions,
    require_gtsam,
)
from mapapi.maps.stored import load_graph
from mapapi.net.shaping import LinkShape, Shaper
from mapapi.service.peer import Peer
from mapbench.lookup import environment
from mapbench.peers import received_bytes, settled_peers, stats_of

log = logging.getLogger(__name__)

SAMPLES = Path(__file__).resolve().parents[1] / "sample_maps"
"""The source tree's sample maps (`sample_maps/README.md`)."""

TUNNELS = "kimera_multi_tunnels_8robots"

MODES = ("decentralized", "centralized")

BANDWIDTHS = {"decentralized": 1_000_000.0, "centralized": 100_000.0}
"""Bytes per second of every link, per mode (issue 5 §6: 1 MB/s, 100 kB/s)."""

DEFAULT_GROUND = 4
DEFAULT_AERIAL = 4
QUICK = {"ground": 2, "aerial": 2, "vertices": 50}
"""`--quick`: 2 ground and 2 aerial missions cut to their first 50 vertices."""

SERVER = "server"


class RegistrationCheckFailed(MapError):
    """The two modes registered the missions differently."""


@dataclass(frozen=True)
class Plan:
    """The missions by role and each ground mission's job (the aerial missions
    near it)."""

    ground: list[MissionGraph]
    aerial: list[MissionGraph]
    jobs: dict[str, list[str]]

    @property
    def missions(self) -> list[MissionGraph]:
        """Ground, then aerial."""
        return [*self.ground, *self.aerial]


def plan(
    ground: int = DEFAULT_GROUND,
    aerial: int = DEFAULT_AERIAL,
    vertices: int | None = None,
    samples: Path = SAMPLES,
) -> Plan:
    """The roles and jobs over the tunnels set: robots 0..ground-1 on the
    ground, the last `aerial` robots in the air; with `vertices`, every
    mission cut to its first `vertices` vertices (edges to cut vertices dropped).

    Raises:
        UsageError: fewer than 1 of each role, more than the set's robots, or
            `vertices` below 2.
        MapImportError: the sample files are missing or malformed.
    """
    graphs = read_kimera(samples / TUNNELS)
    if ground < 1 or aerial < 1 or ground + aerial > len(graphs):
        raise UsageError(
            f"{ground} ground and {aerial} aerial robots do not fit the {len(graphs)} robots "
            "of the tunnels set (at least 1 of each)"
        )
    if vertices is not None:
        if vertices < 2:
            raise UsageError(f"a mission needs at least 2 vertices, not {vertices}")
        graphs = cut(graphs, vertices)
    grounds, aerials = graphs[:ground], graphs[len(graphs) - aerial :]
    names = {g.name for g in aerials}
    return Plan(grounds, aerials, {g.name: linked_missions(g, names) for g in grounds})


def cut(graphs: Sequence[MissionGraph], vertices: int) -> list[MissionGraph]:
    """Each graph's first `vertices` vertices (by index) and the edges among
    the vertices kept in all of them."""
    kept = {g.name: set(sorted(g.vertices)[:vertices]) for g in graphs}

    def inside(end: tuple[str, int]) -> bool:
        return end[1] in kept.get(end[0], ())

    return [
        MissionGraph(
            g.name,
            g.robot,
            g.frame,
            {i: p for i, p in g.vertices.items() if i in kept[g.name]},
            [e for e in g.edges if inside(e.source) and inside(e.target)],
        )
        for g in graphs
    ]


@dataclass
class _Puller:
    """A peer that fetches missions and registers them."""

    peer: Peer
    name: str
    role: str
    fetch: list[str]  # missions to fetch, in order
    jobs: list[str]  # the ground missions whose jobs it runs
    bytes: int = 0
    transfer_s: float = 0.0
    load_s: float = 0.0
    register_s: float = 0.0
    graphs: dict[str, MissionGraph] = field(default_factory=dict)
    results: list[Registration] = field(default_factory=list)


def measure_registration(
    layout: Plan,
    *,
    bandwidths: dict[str, float] | None = None,
    modes: Sequence[str] = MODES,
    seed: int = 0,
) -> dict[str, Any]:
    """Run `layout`'s jobs in each mode, each on a fresh swarm.

    Args:
        layout: the missions and jobs (`plan`).
        bandwidths: bytes per second of every link, per mode (default `BANDWIDTHS`).
        modes: some of `MODES`.
        seed: seeds the peers' ids.

    Returns:
        JSON-ready: ground, aerial (mission names), jobs, elements (vertices
        + edges of all missions), then per mode in `runs`: mode, bandwidth,
        peers (per fetching peer: peer, role, missions fetched, chunks, bytes,
        transfer_s, load_s, register_s, compute_s, total_s), bytes (all
        fetched), wall_s (the slowest peer's total: peers work in parallel)
        and registrations (per job: reference, missions, edges, inliers, the
        RMS residual of the kept edges before and after in metres and
        degrees, and the frames found); then frame_difference_m and _deg (the
        largest difference of a frame between the modes; None with one mode)
        and the machine.

    Raises:
        UsageError: gtsam is missing, or an unknown mode.
        RegistrationError: gtsam failed to optimise a job.
        RingNotStable: a swarm's ring did not converge (a Chord bug).
    """
    require_gtsam()  # before a minute of transfers, not after
    unknown = set(modes) - set(MODES)
    if unknown:
        raise UsageError(f"unknown modes {sorted(unknown)}; choose from {', '.join(MODES)}")
    speeds = {**BANDWIDTHS, **(bandwidths or {})}
    machine = environment()
    runs = [asyncio.run(_run(mode, layout, speeds[mode], seed)) for mode in modes]
    metres, degrees = _difference(runs)
    return {
        "ground": [g.name for g in layout.ground],
        "aerial": [g.name for g in layout.aerial],
        "jobs": layout.jobs,
        "elements": sum(g.elements() for g in layout.missions),
        "runs": runs,
        "frame_difference_m": metres,
        "frame_difference_deg": degrees,
        **machine,
    }


def check_registration(result: dict[str, Any], tolerance: float = 1e-6) -> None:
    """Fail unless every mode found the same frames (within `tolerance` metres
    and degrees) with the same inliers.

    Raises:
        RegistrationCheckFailed: they differ.
    """
    metres, degrees = result["frame_difference_m"], result["frame_difference_deg"]
    inliers = {
        tuple((r["reference"], r["inliers"]) for r in run["registrations"])
        for run in result["runs"]
    }
    if metres is not None and (metres > tolerance or degrees > tolerance or len(inliers) > 1):
        raise RegistrationCheckFailed(
            f"the modes registered the missions differently (frames up to {metres:.3g} m, "
            f"{degrees:.3g} deg apart); reproduce with tests/net/test_bench_registration.py"
        )


async def _run(mode: str, layout: Plan, bandwidth: float, seed: int) -> dict[str, Any]:
    """One mode on a fresh swarm: fetch, read back; then, the swarm closed, register."""
    shapers: list[Shaper] = []

    def shaper() -> Shaper:
        shapers.append(Shaper())  # unshaped while the missions are imported
        return shapers[-1]

    missions = layout.missions
    count = len(missions) + (mode == "centralized")
    async with settled_peers(
        count, random.Random(seed), grid=SpatialGrid(), shaper=shaper
    ) as peers:
        chunks: dict[str, list[ChunkId]] = {}
        for peer, graph in zip(peers, missions, strict=False):
            (result,) = await import_missions(peer, [graph])
            chunks[graph.name] = result.all_chunks()
        pullers = _pullers(mode, layout, peers)
        for each in shapers:
            each.default = LinkShape(bandwidth=bandwidth)
        for peer in peers:
            stats_of(peer).reset()
        for puller in pullers:
            await _fetch(puller, chunks)
            await _load(puller, layout)
    for puller in pullers:
        _register(puller, layout)
    rows = [_peer_row(p) for p in pullers]
    log.info("%s: %s", mode, [(r["peer"], r["total_s"]) for r in rows])
    return {
        "mode": mode,
        "bandwidth": bandwidth,
        "peers": rows,
        "bytes": sum(r["bytes"] for r in rows),
        "wall_s": max((r["total_s"] for r in rows), default=0.0),
        "registrations": [_registration_row(r) for p in pullers for r in p.results],
    }


def _pullers(mode: str, layout: Plan, peers: Sequence[Peer]) -> list[_Puller]:
    """Who fetches what and runs which jobs in `mode`."""
    if mode == "centralized":
        everything = [g.name for g in layout.missions]
        jobs = [name for name, near in layout.jobs.items() if near]
        return [_Puller(peers[-1], SERVER, "server", everything, jobs)]
    return [
        _Puller(
            peer, g.name, "ground", layout.jobs[g.name], [g.name] if layout.jobs[g.name] else []
        )
        for peer, g in zip(peers, layout.ground, strict=False)
    ]


async def _fetch(puller: _Puller, chunks: dict[str, list[ChunkId]]) -> None:
    """Participate in every chunk of the puller's missions, one after another."""
    before, started = received_bytes(puller.peer), time.perf_counter()
    for mission in puller.fetch:
        for chunk in chunks[mission]:
            await puller.peer.participate(chunk)
    puller.transfer_s = time.perf_counter() - started
    puller.bytes = received_bytes(puller.peer) - before


async def _load(puller: _Puller, layout: Plan) -> None:
    """Read every mission the puller's jobs need from its own store."""
    started = time.perf_counter()
    for job in puller.jobs:
        for name in (job, *layout.jobs[job]):
            if name not in puller.graphs:
                puller.graphs[name] = await load_graph(puller.peer, name)
    puller.load_s = time.perf_counter() - started


def _register(puller: _Puller, layout: Plan) -> None:
    started = time.perf_counter()
    for job in puller.jobs:
        incoming = [puller.graphs[name] for name in layout.jobs[job]]
        puller.results.append(register_missions(puller.graphs[job], incoming))
    puller.register_s = time.perf_counter() - started


def _peer_row(puller: _Puller) -> dict[str, Any]:
    compute = puller.load_s + puller.register_s
    return {
        "peer": puller.name,
        "role": puller.role,
        "missions": puller.fetch,
        "chunks": 3 * len(puller.fetch),
        "bytes": puller.bytes,
        "transfer_s": round(puller.transfer_s, 3),
        "load_s": round(puller.load_s, 3),
        "register_s": round(puller.register_s, 3),
        "compute_s": round(compute, 3),
        "total_s": round(puller.transfer_s + compute, 3),
    }


def _registration_row(result: Registration) -> dict[str, Any]:
    return {
        "reference": result.reference,
        "missions": list(result.frames),
        "edges": result.edges,
        "inliers": result.inliers,
        "rms_m_before": round(result.before.metres, 4),
        "rms_m_after": round(result.after.metres, 4),
        "rms_deg_before": round(result.before.degrees, 4),
        "rms_deg_after": round(result.after.degrees, 4),
        "frames": {name: list(pose) for name, pose in result.frames.items()},
    }


def _difference(runs: Sequence[dict[str, Any]]) -> tuple[float | None, float | None]:
    """The largest difference of one frame between two runs (metres, degrees)."""
    if len(runs) < 2:
        return None, None
    metres = degrees = 0.0
    first = {r["reference"]: r["frames"] for r in runs[0]["registrations"]}
    for run in runs[1:]:
        for row in run["registrations"]:
            for name, pose in row["frames"].items():
                other = pose_matrix(tuple(first[row["reference"]][name]))
                delta = invert(other) @ pose_matrix(tuple(pose))
                translation, angle = residuals(delta)
                metres = max(metres, float(translation))
                degrees = max(degrees, math.degrees(float(angle)))
    return metres, degrees
