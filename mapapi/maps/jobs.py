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
from typing import TYPE_CHECKING, Any, Concatenate, ParamSpec, TypeVar

from mapapi.core.errors import UsageError
from mapapi.lookup.spatial import BBox
from mapapi.maps.cloud_file import CLOUD_FORMATS, write_cloud
from mapapi.maps.frames import MISSION, frame_reads, graph_in
from mapapi.maps.g2o import looks_planar, write_g2o
from mapapi.maps.graph import MissionGraph
from mapapi.maps.labels import map_labels
from mapapi.maps.schema import CLOUDS, GRIDS
from mapapi.maps.stored import CLOUD_READ, cloud_at, graph_at
from mapapi.maps.trajectory import TRAJECTORY_FORMATS, trajectory_of, write_kitti, write_tum
from mapapi.service.peer import Peer
from mapapi.service.processes import in_process
from mapapi.service.repo import Repository

if TYPE_CHECKING:
    from mapapi.maps.plot import PlotResult
    from mapapi.maps.world import WorldAlignment

P = ParamSpec("P")
T = TypeVar("T")


BAG = "bag"  # a ROS 2 bag: a folder, so no extension names it (`mapapi.maps.bag_export`)
GRID = "grid"  # nav2's map YAML and PGM, written by the grid operation (`mapapi.maps.grid_ops`)
EXPORT_FORMATS = ("g2o", *TRAJECTORY_FORMATS, *CLOUD_FORMATS, BAG, GRID)
_BY_SUFFIX = {
    **{f".{fmt}": fmt for fmt in EXPORT_FORMATS if fmt not in (BAG, GRID)},
    ".yaml": GRID,
    ".yml": GRID,
}
_AMBIGUOUS = {".txt": TRAJECTORY_FORMATS}  # TUM and KITTI files are both often .txt


def export_format(target: Path, fmt: str | None = None) -> str:
    """The format to write `target` in: `fmt`, else the one its extension names.

    Raises:
        UsageError: an unknown `fmt`, or an extension that names no format or
            more than one (.txt), with no `fmt`.
    """
    if fmt is not None:
        if fmt not in EXPORT_FORMATS:
            raise UsageError(f"unknown format {fmt!r}; expected one of {', '.join(EXPORT_FORMATS)}")
        if fmt in CLOUD_FORMATS and target.suffix.lower() != f".{fmt}":
            # open3d, which writes clouds, picks the format by the extension alone
            raise UsageError(f"a {fmt} file must end in .{fmt}, not {target.name!r}")
        return fmt
    suffix = target.suffix.lower()
    if suffix in _AMBIGUOUS:
        kinds = _AMBIGUOUS[suffix]
        raise UsageError(
            f"{target.name!r} could be a {' or a '.join(kinds)} file; "
            f"pass {' or '.join(f'--format {k}' for k in kinds)}"
        )
    found = _BY_SUFFIX.get(suffix)
    if found is None:
        raise UsageError(
            f"cannot tell the format to write {target.name!r} in from its extension; "
            f"pass --format ({'|'.join(EXPORT_FORMATS)})"
        )
    return found


def export_reads(fmt: str, frame: str = MISSION) -> tuple[str, ...]:
    """The tables an export in `fmt` (one of `EXPORT_FORMATS`) reads, its poses in `frame`.

    Raises:
        UsageError: an unknown frame, or a cloud in the world frame.
    """
    if fmt == BAG:  # poses, points and grids alike
        return (*frame_reads(frame), CLOUDS, GRIDS)
    if fmt not in CLOUD_FORMATS:
        return frame_reads(frame)
    if frame != MISSION:
        raise UsageError("a point cloud is written in its mission's frame (--frame mission)")
    return CLOUD_READ


def export_mission(
    peer: Peer, time: int, mission: str, target: Path, fmt: str, frame: str = MISSION
) -> dict[str, Any]:
    """Write `mission` as of `time` to `target` in `fmt` (`export_format`): a
    graph as g2o (2D when it is planar), its poses as a TUM or KITTI trajectory
    (`mapapi.maps.trajectory`), a cloud as PLY or PCD, poses, points and grid as a
    ROS 2 bag (`mapapi.maps.bag_export`); what was written. A graph's poses are
    in `frame` (`frames.graph_in`).

    Raises:
        UsageError: the mission has nothing of that kind, or no place in `frame`.
        MapImportError: no such mission.
    """
    if fmt == BAG:
        from mapapi.maps.bag_export import export_bag  # numpy and rosbags: for bags only

        return export_bag(peer, time, mission, target, frame)
    if fmt in CLOUD_FORMATS:
        cloud = cloud_at(peer, time, mission)
        if len(cloud.points) == 0:
            raise UsageError(
                f"mission {mission!r} has no point cloud, which a {fmt} file holds; "
                "export its pose graph as .g2o, .tum or .kitti"
            )
        return {"points": write_cloud(cloud, target)}
    graph = graph_in(peer, time, mission, frame)
    if not graph.vertices:
        raise UsageError(
            f"mission {mission!r} has no pose graph (a point cloud has no poses), "
            f"which a {fmt} file holds; export it as .ply or .pcd"
        )
    if fmt == "g2o":
        written = _write_graph(graph, target)
        # edges to other missions' vertices have no place in a one-mission g2o file
        left_out = len(graph.edges) - written
        return {
            "vertices": len(graph.vertices),
            "landmarks": len(graph.landmarks),
            "edges": written,
            "left_out": left_out,
        }
    trajectory = trajectory_of(graph)
    write = write_tum if fmt == "tum" else write_kitti
    with target.open("w", encoding="ascii") as out:
        poses = write(trajectory, out)
    return {"poses": poses, "time": "timestamp" if trajectory.timed else "index"}


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
    frame: str = MISSION,
) -> PlotResult:
    """Draw the missions `chosen` ((name, kind) pairs, kind "cloud" or "graph") as
    of `time` to the PNG `target` (see `mapapi.maps.plot.plot_map`), the graphs'
    poses in `frame`.

    Raises:
        UsageError: in the world frame, a cloud is chosen or a graph was never aligned.
    """
    from mapapi.maps.plot import plot_map

    named = [name for name, kind in chosen if kind == "cloud"]
    if named and frame != MISSION:
        raise UsageError(
            f"point clouds have no place in the {frame} frame: {', '.join(named)}; "
            "choose the pose graphs with --mission"
        )
    graphs = [graph_in(peer, time, name, frame) for name, kind in chosen if kind != "cloud"]
    clouds = [cloud_at(peer, time, name) for name in named]
    return plot_map(target, graphs, clouds, box, up, zoom=zoom, title=title, labels=labels)


def align_at(peer: Peer, time: int, names: list[str], anchor: str | None) -> WorldAlignment:
    """Place the missions `names` as of `time` in one world frame
    (`mapapi.maps.world.align_world`: gtsam, which holds the interpreter lock)."""
    from mapapi.maps.world import align_world

    return align_world([graph_at(peer, time, name) for name in names], anchor)


async def run_job(peer: Peer, job: Callable[..., T], *args: Any) -> T:
    """Run a long map job off the event loop: in a process of its own that opens
    the store, while `peer` serves a swarm (its heartbeats must keep their pace:
    issue 14 §1); else in a worker thread."""
    store = getattr(peer.store, "path", None)
    if peer.swarm is None or not isinstance(store, Path):
        return await peer.off_loop(job, peer, *args)
    return await in_process(in_repository, store, job, *args)


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
