"""g2o pose graphs: a streaming reader and a writer (pure; no network, no store).

Reads `VERTEX_SE2`, `VERTEX_SE3:QUAT`, `EDGE_SE2` and `EDGE_SE3:QUAT` (the
formats in `shared/datasets/README.md` §4). 2D graphs are lifted to 3D: yaw
becomes a rotation about z and the 3x3 information lands on (x, y, rz) of the
6x6 (`se3.lift_information`). An edge `i -> i+1` is odometry, any other a loop.
Graphs that list edges only get their vertices by chaining the odometry.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Iterable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import TextIO

from mapapi.core.errors import UsageError
from mapapi.maps.errors import MapImportError
from mapapi.maps.graph import (
    NO_ORIGIN,
    EdgeKind,
    GraphEdge,
    MissionGraph,
    Origin,
    chain_odometry,
)
from mapapi.maps.se3 import Pose, from_se2, is_planar, lift_information, project_information, yaw

Progress = Callable[[int, int], None]  # (lines read, 0: total unknown while streaming)

# tag -> number of values after the tag
_ARITY = {"VERTEX_SE2": 4, "VERTEX_SE3:QUAT": 8, "EDGE_SE2": 11, "EDGE_SE3:QUAT": 30}
_IGNORED = {"FIX"}  # gauge fixing: says nothing about the graph itself
_PROGRESS_EVERY = 10_000


def read_g2o(
    path: str | Path, mission: str | None = None, robot: str = "", progress: Progress | None = None
) -> MissionGraph:
    """Read a g2o file as one mission (named after the file unless `mission`).

    Raises:
        MapImportError: a line is malformed (the message names it).
    """
    path = Path(path)
    with path.open(encoding="utf-8") as lines:
        return parse_g2o(lines, mission or path.stem, robot, source=str(path), progress=progress)


def parse_g2o(
    lines: Iterable[str],
    mission: str,
    robot: str = "",
    *,
    source: str = "",
    progress: Progress | None = None,
) -> MissionGraph:
    """Parse g2o text line by line into a `MissionGraph`.

    Args:
        lines: the text, one record per line (an open file streams).
        mission: the mission's name.
        robot: the robot's name.
        source: the file name errors mention.
        progress: called every 10,000 lines with (lines read, 0).

    Raises:
        MapImportError: an unknown record, a wrong number of values, a value
            that is not a finite number, a duplicate vertex, or 2D mixed with 3D.
    """
    graph = MissionGraph(mission, robot, frame=f"{mission}/map")
    dims: set[int] = set()
    number = 0
    for number, line in enumerate(lines, 1):
        parsed = _record(line, source, number)
        if parsed is None:
            continue
        tag, values = parsed
        dims.add(2 if tag.endswith("SE2") else 3)
        if len(dims) > 1:
            raise MapImportError("2D and 3D records mixed in one graph", source=source, line=number)
        origin = Origin(number, line.rstrip("\r\n"))
        if tag.startswith("VERTEX"):
            _add_vertex(graph, tag, values, source, number)
            graph.origins[_index(values[0], source, number)] = origin
        else:
            graph.edges.append(_edge(mission, tag, values, source, number, origin))
        if progress is not None and number % _PROGRESS_EVERY == 0:
            progress(number, 0)
    graph.planar = dims == {2}
    ends = {e.source[1] for e in graph.edges} | {e.target[1] for e in graph.edges}
    chain_odometry(graph, ends)
    if progress is not None:
        progress(number, number)
    return graph


def _record(line: str, source: str, number: int) -> tuple[str, list[float]] | None:
    """(tag, values) of one line; None for a blank, comment or ignored line.

    Raises:
        MapImportError: an unknown record, a wrong number of values, or a value
            that is not a finite number.
    """
    parts = line.split()
    if not parts or parts[0].startswith("#") or parts[0] in _IGNORED:
        return None
    tag = parts[0]
    arity = _ARITY.get(tag)
    if arity is None:
        raise MapImportError(
            f"unsupported record {tag!r}; expected one of {', '.join(_ARITY)}",
            source=source,
            line=number,
        )
    if len(parts) != arity + 1:
        raise MapImportError(
            f"{tag} needs {arity} values, found {len(parts) - 1}", source=source, line=number
        )
    try:
        return tag, _numbers(parts)
    except ValueError as exc:
        raise MapImportError(f"{tag}: {exc}", source=source, line=number) from None


def _numbers(parts: list[str]) -> list[float]:
    values = [float(v) for v in parts[1:]]
    if not math.isfinite(math.fsum(values)):
        raise ValueError("values must be finite numbers")
    return values


def _index(value: float, source: str, line: int) -> int:
    index = int(value)
    if index != value or index < 0:
        raise MapImportError(
            f"vertex id {value!r} is not a natural number", source=source, line=line
        )
    return index


def _quaternion(pose: Pose, source: str, line: int) -> Pose:
    norm = math.sqrt(pose[3] ** 2 + pose[4] ** 2 + pose[5] ** 2 + pose[6] ** 2)
    if abs(norm - 1.0) > 1e-3:
        raise MapImportError(
            f"quaternion norm {norm:.6g} is not 1 (order is qx qy qz qw)", source=source, line=line
        )
    return pose


def _add_vertex(graph: MissionGraph, tag: str, v: list[float], source: str, line: int) -> None:
    index = _index(v[0], source, line)
    if index in graph.vertices:
        raise MapImportError(f"vertex {index} is defined twice", source=source, line=line)
    graph.vertices[index] = _vertex_pose(tag, v, source, line)


def _vertex_pose(tag: str, v: list[float], source: str, line: int) -> Pose:
    if tag == "VERTEX_SE2":
        return from_se2(v[1], v[2], v[3])
    return _quaternion((v[1], v[2], v[3], v[4], v[5], v[6], v[7]), source, line)


def _edge(
    mission: str, tag: str, v: list[float], source: str, line: int, origin: Origin = NO_ORIGIN
) -> GraphEdge:
    i, j = _index(v[0], source, line), _index(v[1], source, line)
    if tag == "EDGE_SE2":
        relative = from_se2(v[2], v[3], v[4])
        information = lift_information(tuple(v[5:11]))
    else:
        relative = _quaternion((v[2], v[3], v[4], v[5], v[6], v[7], v[8]), source, line)
        information = tuple(v[9:30])
    kind = EdgeKind.ODOMETRY if j == i + 1 else EdgeKind.LOOP
    return GraphEdge((mission, i), (mission, j), relative, information, kind, origin)


def looks_planar(graph: MissionGraph) -> bool:
    """True when the mission says nothing a 2D (SE2) g2o file cannot: every pose
    and edge lies in the plane and the information only weighs x, y and yaw."""
    if not all(is_planar(p) for p in graph.vertices.values()):
        return False
    return all(
        is_planar(e.relative)
        and lift_information(project_information(e.information)) == tuple(e.information)
        for e in graph.edges
    )


def write_g2o(graph: MissionGraph, out: TextIO, *, planar: bool | None = None) -> int:
    """Write a mission as g2o text; returns how many edges were written.

    Records come in their import order (`Origin.line`; vertices without one
    first, by index), and a record whose original text still says what it
    holds is written as that text, so an imported file comes back byte for
    byte (less its comments, blank and FIX lines). Other records are written
    from their values, floats in their shortest exact form, so a 3D export
    reads back to the same numbers. Edges to other missions' vertices cannot be
    expressed in one g2o file and are left out, as are edges to vertices the
    graph lacks (a mission held here in part: its tiles outside a box loaded).

    Args:
        planar: write VERTEX_SE2/EDGE_SE2; default: when the graph came from 2D.

    Raises:
        UsageError: `planar` was asked of a graph that leaves the plane.
    """
    if planar is None:
        planar = graph.planar
    if planar and not all(is_planar(p) for p in graph.vertices.values()):
        raise UsageError(f"mission {graph.name!r} is not planar; export it as 3D")
    lines: list[tuple[int, int, int, str]] = []
    for index, pose in graph.vertices.items():
        origin = graph.origins.get(index, NO_ORIGIN)
        lines.append((origin.line, 0, index, _vertex_line(index, pose, origin, planar)))
    for position, edge in enumerate(graph.edges):
        ends = (edge.source, edge.target)
        if all(m == graph.name and i in graph.vertices for m, i in ends):
            lines.append((edge.origin.line, 1, position, _edge_line(edge, planar)))
    lines.sort(key=lambda record: record[:3])
    out.writelines(f"{text}\n" for *_, text in lines)
    return sum(1 for record in lines if record[1] == 1)


def lean_origin(origin: Origin, tag: str, values: Sequence[float]) -> Origin:
    """`origin` without its text when its number formatting (`Origin.digits`)
    writes `values` after `tag` as exactly that text (the row then holds its
    numbers once; an edge's text was 40 % of its row), else `origin`."""
    digits = _digits(origin.text)
    lean = Origin(origin.line, "", digits or b"")
    if digits is None or _written(lean, tag, values) != origin.text:
        return origin
    return lean


def lean_vertex(index: int, pose: Pose, origin: Origin, planar: bool) -> Origin:
    """The vertex's `origin` for its row (`lean_origin`); `planar` as imported."""
    return lean_origin(origin, *_vertex_values(index, pose, planar))


def lean_edge(edge: GraphEdge, planar: bool) -> GraphEdge:
    """The edge with the origin for its row (`lean_origin`); `planar` as imported."""
    lean = lean_origin(edge.origin, *_edge_values(edge, planar))
    return edge if lean is edge.origin else replace(edge, origin=lean)


_NUMBER = re.compile(r"-?\d+(?:\.(\d+))?")


def _digits(text: str) -> bytes | None:
    """The decimals of each number after the tag of a g2o line; None when a
    number is not plain fixed-point (an exponent, a plus sign, over 255 decimals)."""
    _, *numbers = text.split(" ")
    out = bytearray()
    for number in numbers:
        match = _NUMBER.fullmatch(number)
        decimals = len(match.group(1) or "") if match else 256
        if decimals > 255:
            return None
        out.append(decimals)
    return bytes(out) if out else None


def _written(origin: Origin, tag: str, values: Sequence[float]) -> str | None:
    """The record's text as read: kept, or written again from `values` with its
    formatting; None when there is neither (or the formatting is for other values)."""
    if origin.text:
        return origin.text
    if not origin.digits or len(origin.digits) != len(values):
        return None
    return " ".join([tag, *(f"{v:.{d}f}" for v, d in zip(values, origin.digits, strict=True))])


def _vertex_values(index: int, pose: Pose, planar: bool) -> tuple[str, list[float]]:
    if planar:
        return "VERTEX_SE2", [index, pose[0], pose[1], yaw(pose)]
    return "VERTEX_SE3:QUAT", [index, *pose]


def _edge_values(edge: GraphEdge, planar: bool) -> tuple[str, list[float]]:
    ends, rel = [edge.source[1], edge.target[1]], edge.relative
    if planar:
        info = project_information(edge.information)
        return "EDGE_SE2", [*ends, rel[0], rel[1], yaw(rel), *info]
    return "EDGE_SE3:QUAT", [*ends, *rel, *edge.information]


def _vertex_line(index: int, pose: Pose, origin: Origin, planar: bool) -> str:
    """The vertex's text as read while it still says `index` and `pose`, else
    the line its values give."""
    tag, values = _vertex_values(index, pose, planar)
    text = _written(origin, tag, values)
    read = _reread(text, planar)
    if text and read is not None and read[1][0] == index and _vertex_pose(*read, "", 0) == pose:
        return text
    return _plain(tag, values)


def _edge_line(edge: GraphEdge, planar: bool) -> str:
    """The edge's text as read while it still says what the edge holds, else
    the line its values give."""
    tag, values = _edge_values(edge, planar)
    text = _written(edge.origin, tag, values)
    read = _reread(text, planar)
    if text and read is not None:
        again = _edge(edge.source[0], *read, "", 0)
        if (again.source, again.target, again.relative, again.information) == (
            edge.source,
            edge.target,
            edge.relative,
            edge.information,
        ):
            return text
    return _plain(tag, values)


def _plain(tag: str, values: Sequence[float]) -> str:
    """A record written from its values, floats in their shortest exact form."""
    return " ".join([tag, *(repr(v) for v in values)])


def _reread(text: str | None, planar: bool) -> tuple[str, list[float]] | None:
    """(tag, values) of a record's text as read, of the dimension being written;
    None when there is none (or it no longer parses, which a stored row never should)."""
    if not text:
        return None
    try:
        read = _record(text, "", 0)
    except (MapImportError, ValueError):
        return None
    if read is None or read[0].endswith("SE2") != planar:
        return None
    return read
