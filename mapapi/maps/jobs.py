"""The long map jobs, exporting and drawing missions, off the peer's event loop
(issue 14 §1).

A job is a plain function over a `Peer` and a read time (`stored.read_time`):
it reads the missions, decodes them and writes a file or draws a picture. In
a peer daemon that serves a swarm, `MapOperations` runs it in a process of its
own (`in_repository`, through `mapapi.service.processes.in_process`), which
opens the repository's store itself: a thread would still share the daemon's
interpreter lock and garbage collector with the loop, and a mission of 100,000
rows decoded beside it stalled heartbeats for up to a second (measured, see
docs/benchmarks.md). Elsewhere (a command run without a daemon) it runs in a
worker thread of the caller. SQLite lets any number of processes read one
store; the read time makes what the job reads the mission as of that time.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Concatenate, ParamSpec, TypeVar

from mapapi.core.errors import UsageError
from mapapi.lookup.spatial import BBox
from mapapi.maps.cloud_file import CLOUD_FORMATS, write_cloud
from mapapi.maps.g2o import looks_planar, write_g2o
from mapapi.maps.graph import MissionGraph
from mapapi.maps.labels import map_labels
from mapapi.maps.stored import CLOUD_READ, GRAPH_READ, cloud_at, graph_at
from mapapi.service.peer import Peer
from mapapi.service.repo import Repository

if TYPE_CHECKING:
    from mapapi.maps.plot import PlotResult

P = ParamSpec("P")
T = TypeVar("T")


def export_reads(target: Path) -> tuple[str, ...]:
    """The tables an export to `target` reads (by its extension).

    Raises:
        UsageError: not a .g2o, .ply or .pcd file.
    """
    fmt = target.suffix.lower().lstrip(".")
    if fmt == "g2o":
        return GRAPH_READ
    if fmt in CLOUD_FORMATS:
        return CLOUD_READ
    raise UsageError(f"export to a .g2o, .ply or .pcd file, not {target.name!r}")


def export_mission(peer: Peer, time: int, mission: str, target: Path) -> dict[str, int]:
    """Write `mission` as of `time` to `target`: a graph as g2o (2D when it is
    planar), a cloud as PLY or PCD, by the extension; what was written.

    Raises:
        UsageError: the mission has nothing of that kind, or a bad extension.
        MapImportError: no such mission.
    """
    if export_reads(target) == GRAPH_READ:
        graph = graph_at(peer, time, mission)
        if not graph.vertices:
            raise UsageError(f"mission {mission!r} has no pose graph; export it as .ply")
        written = _write_graph(graph, target)
        # edges to other missions' vertices have no place in a one-mission g2o file
        left_out = len(graph.edges) - written
        return {
            "vertices": len(graph.vertices),
            "landmarks": len(graph.landmarks),
            "edges": written,
            "left_out": left_out,
        }
    cloud = cloud_at(peer, time, mission)
    if len(cloud.points) == 0:
        raise UsageError(f"mission {mission!r} has no point cloud; export it as .g2o")
    return {"points": write_cloud(cloud, target)}


def draw_missions(
    peer: Peer,
    time: int,
    chosen: list[tuple[str, str]],
    target: Path,
    box: BBox | None,
    up: str,
    zoom: bool,
    title: str | None,
    labels: Mapping[str, str] | None,
) -> PlotResult:
    """Draw the missions `chosen` ((name, kind) pairs, kind "cloud" or "graph") as
    of `time` to the PNG `target` (see `mapapi.maps.plot.plot_map`)."""
    from mapapi.maps.plot import plot_map

    graphs = [graph_at(peer, time, name) for name, kind in chosen if kind != "cloud"]
    clouds = [cloud_at(peer, time, name) for name, kind in chosen if kind == "cloud"]
    return plot_map(target, graphs, clouds, box, up, zoom=zoom, title=title, labels=labels)


def in_repository(
    store: Path, job: Callable[Concatenate[Peer, P], T], *args: P.args, **kwargs: P.kwargs
) -> T:
    """What a job's process runs: open the peer of the repository whose store file
    is `store` (its store only: no network; it only reads), run `job` on it."""
    peer = Peer.of(Repository.find(store), labels=map_labels())
    try:
        return job(peer, *args, **kwargs)
    finally:
        peer.store.close()


def _write_graph(graph: MissionGraph, target: Path) -> int:
    with target.open("w", encoding="utf-8") as out:
        return write_g2o(graph, out, planar=looks_planar(graph))
