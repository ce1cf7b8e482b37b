"""`mapctl bench scale`: what each read command costs as a repository holds more
missions (issue 14 §2: cost follows the mission, not the repository).

One fresh repository grows to each count M of missions in turn: M copies of
one real pose graph, each a mission of its own (`<stem>-000`, `<stem>-001`,
...) moved aside so that no two missions' boxes overlap (copy k sits in cell k
of a 10-wide grid of the graph's size plus a margin). At each M every read
command of `mapctl` runs `runs` times on the first copy, through the
operations the CLI calls (`mapapi.app.operations`, as `mapctl` runs them on a
repository whose peer is not running): `missions`, `export` of the mission to
g2o, `plot` of the mission, `query-bbox --load` of the mission's box (nothing
to fetch: every chunk is held here) and `ls` of its first vertices tile (its
whole vertices chunk before tiles). The figures are the median seconds of each,
after one untimed pass at the first count (which loads matplotlib and the
like); a flat curve against M is the goal.
Nothing here asserts a time; the figures go to docs/benchmarks.md.
"""

from __future__ import annotations

import asyncio
import statistics
import tempfile
import time
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

from mapapi.app import operations, peer_of
from mapapi.core.errors import UsageError
from mapapi.maps.graph import MissionGraph
from mapapi.maps.importer import ImportResult, import_graph
from mapapi.maps.schema import VERTICES
from mapapi.maps.se3 import Pose
from mapapi.maps.source import read_source
from mapapi.service.ops import Operations
from mapapi.service.repo import Repository
from mapapi.store.file_check import store_bytes
from mapbench.lookup import environment
from mapbench.maps import SAMPLES

DEFAULT_GRAPH = SAMPLES / "pose_graphs" / "intel.g2o"
"""The graph `measure_scale` copies unless given one (small: a quick run)."""

DEFAULT_COUNTS = (1, 10)
"""The mission counts of a quick run (the issue's are 1, 10 and 100)."""

READS = ("missions", "export", "plot", "query_bbox_load", "ls")
"""The read commands timed at each count, in this order."""

TARGETS = {"missions": 0.2, "plot": 3.0}
"""Issue 14's targets in seconds, with 10 missions of 15k poses held (export's is
relative: within 1.5 times its time with one mission held)."""

_COLUMNS = 10  # copies per row of the grid that keeps their boxes apart
_MARGIN = 10.0  # metres between two copies


def parse_counts(text: str) -> list[int]:
    """Mission counts from "1,10,100" (sorted, without repeats).

    Raises:
        UsageError: not a comma-separated list of positive integers.
    """
    try:
        counts = sorted({int(part) for part in text.split(",") if part.strip()})
    except ValueError:
        raise UsageError(f"--missions takes counts such as 1,10,100, not {text!r}") from None
    if not counts or counts[0] < 1:
        raise UsageError(f"--missions takes positive counts such as 1,10,100, not {text!r}")
    return counts


def measure_scale(
    counts: Sequence[int],
    graph: str | Path = DEFAULT_GRAPH,
    *,
    runs: int = 3,
    directory: str | Path | None = None,
    label: str = "",
) -> dict[str, Any]:
    """Time every read command of one mission at each count of missions held.

    Args:
        counts: the numbers of missions the repository holds when the reads
            are timed (it grows from one to the next).
        graph: a g2o file holding one pose graph, copied as every mission.
        runs: timed runs of each read at each count (the median counts).
        directory: where the scratch repository goes (default: the system's).
        label: names the run in plots ("before", "after"); kept in the figures.

    Returns:
        JSON-ready figures: the graph, its vertices and edges, runs, and per
        count (`points`) the missions held, the store's bytes (file plus WAL),
        the seconds the copies took to import, and per read the median
        seconds (`seconds`) and every run (`runs_s`); plus the machine.

    Raises:
        UsageError: no counts, a count below 1, no runs, or a file that holds
            no single pose graph.
    """
    wanted = sorted(set(counts))
    if not wanted or wanted[0] < 1:
        raise UsageError("give at least one mission count, each 1 or more")
    if runs < 1:
        raise UsageError(f"runs must be at least 1, not {runs}")
    machine = environment()
    source = _one_graph(Path(graph))
    with tempfile.TemporaryDirectory(prefix="mapapi-scale-", dir=directory) as tmp:
        points = asyncio.run(_grow_and_read(source, wanted, runs, Path(tmp)))
    return {
        "label": label,
        "graph": Path(graph).name,
        "vertices": len(source.vertices),
        "edges": len(source.edges),
        "runs": runs,
        "points": points,
        **machine,
    }


def _one_graph(path: Path) -> MissionGraph:
    sources = read_source(path)
    if len(sources) != 1 or not isinstance(sources[0], MissionGraph):
        raise UsageError(f"{path} holds no single pose graph; give a g2o file")
    return sources[0]


def copy_of(graph: MissionGraph, k: int) -> MissionGraph:
    """Copy `k` of `graph`: mission `<name>-<k>` (robot likewise), moved to cell
    k of the grid, so that no two copies' boxes overlap."""
    box = graph.bbox()
    assert box is not None  # a parsed graph has vertices
    width = box.xmax - box.xmin + _MARGIN
    depth = box.ymax - box.ymin + _MARGIN
    dx, dy = (k % _COLUMNS) * width, (k // _COLUMNS) * depth
    name = f"{graph.name}-{k:03d}"

    def moved(pose: Pose) -> Pose:
        return (pose[0] + dx, pose[1] + dy, *pose[2:])

    renamed = replace(graph, vertices={i: moved(p) for i, p in graph.vertices.items()})
    return replace(
        renamed,
        name=name,
        robot=name,
        frame=f"{name}/map",
        edges=[
            replace(
                e,
                source=(name, e.source[1]) if e.source[0] == graph.name else e.source,
                target=(name, e.target[1]) if e.target[0] == graph.name else e.target,
            )
            for e in graph.edges
        ],
    )


async def _grow_and_read(
    graph: MissionGraph, counts: list[int], runs: int, scratch: Path
) -> list[dict[str, Any]]:
    repo = Repository.init(scratch / "repo", "bench")
    peer = peer_of(repo)
    points: list[dict[str, Any]] = []
    try:
        ops = operations(peer)
        first: ImportResult | None = None
        held = 0
        for count in counts:
            started = time.perf_counter()
            while held < count:
                result = await import_graph(peer, copy_of(graph, held))
                first = first or result
                held += 1
            imported = time.perf_counter() - started
            assert first is not None
            reads = _reads(ops, first, scratch)
            if count == counts[0]:
                await _time_reads(reads, 1)  # warm-up: imports (matplotlib) are no read's cost
            timed = await _time_reads(reads, runs)
            points.append(
                {
                    "missions": count,
                    "store_bytes": store_bytes(repo.store_path),
                    "import_s": round(imported, 3),
                    "seconds": {k: round(statistics.median(v), 4) for k, v in timed.items()},
                    "runs_s": {k: [round(s, 4) for s in v] for k, v in timed.items()},
                }
            )
    finally:
        await peer.close()
    return points


Read = Callable[[], Awaitable[Any]]


def _reads(ops: Operations, mission: ImportResult, scratch: Path) -> dict[str, Read]:
    """The read commands on `mission`, as `mapctl` calls them."""
    box = list(mission.bbox.as_tuple()) if mission.bbox is not None else None
    calls: dict[str, tuple[str, dict[str, Any]]] = {
        "missions": ("missions", {}),
        "export": ("export_map", {"mission": mission.mission, "path": str(scratch / "out.g2o")}),
        "plot": ("plot_map", {"path": str(scratch / "out.png"), "missions": [mission.mission]}),
        "query_bbox_load": ("load_bbox", {"bbox": box}),
        "ls": ("ls", {"view": "main", "table": VERTICES, "chunk": mission.tiles[0].vertices}),
    }
    return {name: _caller(ops, *calls[name]) for name in READS}


def _caller(ops: Operations, op: str, args: dict[str, Any]) -> Read:
    async def call() -> Any:
        return await ops.call(op, args)

    return call


async def _time_reads(reads: dict[str, Read], runs: int) -> dict[str, list[float]]:
    """Seconds of each run of each read (the reads take turns, run by run)."""
    timed: dict[str, list[float]] = {name: [] for name in reads}
    for _ in range(runs):
        for name, read in reads.items():
            started = time.perf_counter()
            await read()
            timed[name].append(time.perf_counter() - started)
    return timed
