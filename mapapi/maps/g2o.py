"""g2o pose graphs: a streaming reader and a writer (pure; no network, no store).

Reads `VERTEX_SE2`, `VERTEX_SE3:QUAT`, `EDGE_SE2` and `EDGE_SE3:QUAT` (the
formats in `shared/datasets/README.md` §4), and 2D landmarks: `VERTEX_XY` and
their observations `EDGE_SE2_XY` (`mapapi.maps.g2o_records`). 2D graphs are
lifted to 3D: yaw becomes a rotation about z and the 3x3 information lands on
(x, y, rz) of the 6x6 (`se3.lift_information`). An edge `i -> i+1` is odometry,
any other a loop. Graphs that list edges only get their vertices by chaining the
odometry, and landmarks observed but not listed a position from their first
observation (`graph.place_landmarks`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import replace
from pathlib import Path
from typing import TextIO

from mapapi.core.errors import UsageError
from mapapi.maps.errors import MapImportError
from mapapi.maps.g2o_records import (
    LANDMARK_VERTEX,
    PLANAR_TAGS,
    edge_line,
    edge_of,
    index,
    landmark_line,
    landmark_point,
    parse_record,
    vertex_line,
    vertex_pose,
)
from mapapi.maps.graph import (
    NO_ORIGIN,
    EdgeKind,
    GraphEdge,
    MissionGraph,
    Origin,
    chain_odometry,
    place_landmarks,
)
from mapapi.maps.se3 import XY_AXES, is_planar, lift_information, project_information
from mapapi.maps.text_file import read_text

Progress = Callable[[int, int], None]  # (lines read, 0: total unknown while streaming)

_PROGRESS_EVERY = 10_000


def read_g2o(
    path: str | Path, mission: str | None = None, robot: str = "", progress: Progress | None = None
) -> MissionGraph:
    """Read a g2o file as one mission (named after the file unless `mission`).

    Raises:
        MapImportError: a line is malformed (the message names it).
    """
    return read_text(parse_g2o, path, mission, robot, progress)


def parse_g2o(
    lines: Iterable[str],
    mission: str,
    robot: str = "",
    *,
    source: str = "",
    progress: Progress | None = None,
    finish: bool = True,
) -> MissionGraph:
    """Parse g2o text line by line into a `MissionGraph`.

    Args:
        lines: the text, one record per line (an open file streams).
        mission: the mission's name.
        robot: the robot's name.
        source: the file name errors mention.
        progress: called every 10,000 lines with (lines read, 0).
        finish: chain the trajectory where vertices are missing and place the
            landmarks (`finish_graph`); False leaves the records as they are,
            for the per-robot reader (`mapapi.maps.dgs`) to split them first.

    Raises:
        MapImportError: an unknown record, a wrong number of values, a value
            that is not a finite number, a duplicate vertex, 2D mixed with 3D,
            or a landmark id used as a pose's (or the other way round).
    """
    graph = MissionGraph(mission, robot, frame=f"{mission}/map")
    dims: set[int] = set()
    number = 0
    for number, line in enumerate(lines, 1):
        parsed = parse_record(line, source, number)
        if parsed is None:
            continue
        tag, values = parsed
        dims.add(2 if tag in PLANAR_TAGS else 3)
        if len(dims) > 1:
            raise MapImportError("2D and 3D records mixed in one graph", source=source, line=number)
        origin = Origin(number, line.rstrip("\r\n"))
        if tag.startswith("VERTEX"):
            _add_vertex(graph, tag, values, origin, source)
        else:
            graph.edges.append(edge_of(mission, tag, values, source, number, origin))
        if progress is not None and number % _PROGRESS_EVERY == 0:
            progress(number, 0)
    graph.planar = dims == {2}
    if finish:
        finish_graph(graph, source)
    if progress is not None:
        progress(number, number)
    return graph


def _add_vertex(
    graph: MissionGraph, tag: str, values: list[float], origin: Origin, source: str
) -> None:
    """One vertex or landmark; g2o ids are one namespace, poses and landmarks alike."""
    at = index(values[0], source, origin.line)
    if at in graph.vertices or at in graph.landmarks:
        raise MapImportError(f"vertex {at} is defined twice", source=source, line=origin.line)
    if tag == LANDMARK_VERTEX:
        graph.landmarks[at] = landmark_point(values)
        graph.landmark_origins[at] = origin
    else:
        graph.vertices[at] = vertex_pose(tag, values, source, origin.line)
        graph.origins[at] = origin


def finish_graph(graph: MissionGraph, source: str = "") -> None:
    """Give the vertices the edges name but the records did not list a pose by
    chaining the odometry, and the landmarks observed a position from their
    first observation.

    Raises:
        MapImportError: an edge takes a landmark for a pose, or the other way round.
    """
    poses: set[int] = set()
    for edge in graph.edges:
        poses.add(edge.source[1])
        landmark = edge.kind is EdgeKind.LANDMARK
        if not landmark:
            poses.add(edge.target[1])
        clash = edge.target[1] in (graph.vertices if landmark else graph.landmarks)
        if clash or edge.source[1] in graph.landmarks:
            raise MapImportError(
                "an edge names a landmark where a pose belongs, or a pose as a landmark",
                source=source,
                line=edge.origin.line,
            )
    chain_odometry(graph, poses)
    place_landmarks(graph)


def looks_planar(graph: MissionGraph) -> bool:
    """True when the mission says nothing a 2D (SE2) g2o file cannot: every pose,
    landmark and edge lies in the plane and the information only weighs x, y and
    yaw (a landmark observation's x and y)."""
    if not all(is_planar(p) for p in graph.vertices.values()):
        return False
    if any(point[2] != 0.0 for point in graph.landmarks.values()):
        return False
    return all(_planar_edge(e) for e in graph.edges)


def _planar_edge(edge: GraphEdge) -> bool:
    info = tuple(edge.information)
    if edge.kind is EdgeKind.LANDMARK:
        flat = edge.relative[2:] == (0.0, 0.0, 0.0, 0.0, 1.0)
        return flat and lift_information(project_information(info, XY_AXES), XY_AXES) == info
    return is_planar(edge.relative) and lift_information(project_information(info)) == info


def write_g2o(graph: MissionGraph, out: TextIO, *, planar: bool | None = None) -> int:
    """Write a mission as g2o text; returns how many edges were written.

    Records come in their import order (`Origin.line`; vertices and landmarks
    without one first, by index), and a record whose original text still says
    what it holds is written as that text, so an imported file comes back byte
    for byte (less its comments, blank and FIX lines). Other records are written
    from their values, floats in their shortest exact form, so a 3D export
    reads back to the same numbers. Edges to other missions' vertices cannot be
    expressed in one g2o file and are left out, as are edges to vertices the
    graph lacks (a mission held here in part: its tiles outside a box loaded).
    g2o ids are one namespace: when landmark indices repeat pose indices (a
    GTSAM landmark file numbers them apart), landmarks are written after the
    last pose's id (`landmark_shift`).

    Args:
        planar: write VERTEX_SE2/EDGE_SE2; default: when the graph came from 2D.

    Raises:
        UsageError: `planar` was asked of a graph that leaves the plane, or a
            graph with landmarks (2D records only) leaves the plane.
    """
    if planar is None:
        planar = graph.planar
    if planar and not all(is_planar(p) for p in graph.vertices.values()):
        raise UsageError(f"mission {graph.name!r} is not planar; export it as 3D")
    if graph.landmarks and not (planar and looks_planar(graph)):
        raise UsageError(
            f"mission {graph.name!r} has landmarks, which g2o holds in 2D only "
            "(VERTEX_XY, EDGE_SE2_XY), and leaves the plane"
        )
    shift = landmark_shift(graph)
    lines: list[tuple[int, int, int, str]] = []
    for at, pose in graph.vertices.items():
        origin = graph.origins.get(at, NO_ORIGIN)
        lines.append((origin.line, 0, at, vertex_line(at, pose, origin, planar)))
    for at, point in graph.landmarks.items():
        origin = graph.landmark_origins.get(at, NO_ORIGIN)
        lines.append((origin.line, 0, at + shift, landmark_line(at + shift, point, origin)))
    for position, edge in enumerate(graph.edges):
        written = _in_file(graph, edge, shift)
        if written is not None:
            lines.append((edge.origin.line, 1, position, edge_line(written, planar)))
    lines.sort(key=lambda record: record[:3])
    out.writelines(f"{text}\n" for *_, text in lines)
    return sum(1 for record in lines if record[1] == 1)


def landmark_shift(graph: MissionGraph) -> int:
    """What a g2o file adds to each landmark index: 0, unless some landmark
    index is also a pose's, then one past the highest pose index."""
    if graph.landmarks.keys() & graph.vertices.keys():
        return max(graph.vertices) + 1
    return 0


def _in_file(graph: MissionGraph, edge: GraphEdge, shift: int) -> GraphEdge | None:
    """The edge as the file names its ends, or None when an end is not in it."""
    name = graph.name
    if edge.source[0] != name or edge.source[1] not in graph.vertices or edge.target[0] != name:
        return None
    if edge.kind is not EdgeKind.LANDMARK:
        return edge if edge.target[1] in graph.vertices else None
    if edge.target[1] not in graph.landmarks:
        return None
    return replace(edge, target=(name, edge.target[1] + shift)) if shift else edge
