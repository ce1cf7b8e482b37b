"""g2o records, one line each: the text as (tag, values), values as vertices,
landmarks and edges, and back; and the number formatting an import keeps so
export writes a record as it was read (`lean_origin`). Pure: no file, no store.

Records: `VERTEX_SE2`, `VERTEX_SE3:QUAT`, `EDGE_SE2`, `EDGE_SE3:QUAT`, and the
2D landmark records `VERTEX_XY id x y` and `EDGE_SE2_XY pose landmark dx dy I11
I12 I22` (g2o's `types_slam2d`). Ids are read as integers from their text: a
GTSAM `Symbol` key (a robot letter in the top 8 bits of 64) does not survive a
float, whose mantissa has 53 bits.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import replace

from mapapi.maps.errors import MapImportError
from mapapi.maps.graph import NO_ORIGIN, EdgeKind, GraphEdge, Origin, Point
from mapapi.maps.se3 import XY_AXES, Pose, from_se2, lift_information, project_information, yaw
from mapapi.maps.text_file import check_arity

# tag -> number of values after the tag
ARITY = {
    "VERTEX_SE2": 4,
    "VERTEX_SE3:QUAT": 8,
    "EDGE_SE2": 11,
    "EDGE_SE3:QUAT": 30,
    "VERTEX_XY": 3,
    "EDGE_SE2_XY": 7,
}
PLANAR_TAGS = frozenset({"VERTEX_SE2", "EDGE_SE2", "VERTEX_XY", "EDGE_SE2_XY"})
LANDMARK_VERTEX, LANDMARK_EDGE = "VERTEX_XY", "EDGE_SE2_XY"
_IGNORED = {"FIX"}  # gauge fixing: says nothing about the graph itself

Record = tuple[str, list[float]]  # (tag, values); ids are ints


def parse_record(line: str, source: str, number: int) -> Record | None:
    """(tag, values) of one line; None for a blank, comment or ignored line.

    Raises:
        MapImportError: an unknown record, a wrong number of values, or a value
            that is not a finite number.
    """
    parts = line.split()
    if not parts or parts[0].startswith("#") or parts[0] in _IGNORED:
        return None
    tag = check_arity(parts, ARITY, source, number)
    try:
        return tag, _numbers(parts, 1 if tag.startswith("VERTEX") else 2)
    except ValueError as exc:
        raise MapImportError(f"{tag}: {exc}", source=source, line=number) from None


def _numbers(parts: list[str], ids: int) -> list[float]:
    values: list[float] = [_id_value(v) for v in parts[1 : 1 + ids]]
    values += [float(v) for v in parts[1 + ids :]]
    if not math.isfinite(math.fsum(values)):
        raise ValueError("values must be finite numbers")
    return values


def _id_value(text: str) -> float:
    """An id as read: an int when it is written as one (exact at 64 bits)."""
    try:
        return int(text)
    except ValueError:
        return float(text)  # `index` refuses it unless it is a whole number


def index(value: float, source: str, line: int) -> int:
    """A vertex id as a natural number.

    Raises:
        MapImportError: it is not one.
    """
    whole = int(value)
    if whole != value or whole < 0:
        raise MapImportError(
            f"vertex id {value!r} is not a natural number", source=source, line=line
        )
    return whole


def _quaternion(pose: Pose, source: str, line: int) -> Pose:
    norm = math.sqrt(pose[3] ** 2 + pose[4] ** 2 + pose[5] ** 2 + pose[6] ** 2)
    if abs(norm - 1.0) > 1e-3:
        raise MapImportError(
            f"quaternion norm {norm:.6g} is not 1 (order is qx qy qz qw)", source=source, line=line
        )
    return pose


def vertex_pose(tag: str, v: list[float], source: str, line: int) -> Pose:
    """The pose of a `VERTEX_SE2` or `VERTEX_SE3:QUAT` record's values.

    Raises:
        MapImportError: a quaternion that is not a unit.
    """
    if tag == "VERTEX_SE2":
        return from_se2(v[1], v[2], v[3])
    return _quaternion((v[1], v[2], v[3], v[4], v[5], v[6], v[7]), source, line)


def landmark_point(v: list[float]) -> Point:
    """The position of a `VERTEX_XY` record's values (z = 0)."""
    return (v[1], v[2], 0.0)


def edge_of(
    mission: str, tag: str, v: list[float], source: str, line: int, origin: Origin = NO_ORIGIN
) -> GraphEdge:
    """The edge of an `EDGE_*` record's values, both ends in `mission`: `i -> i+1`
    is odometry, another pose edge a loop, an `EDGE_SE2_XY` a landmark observation.

    Raises:
        MapImportError: an id that is not natural, or a quaternion not a unit.
    """
    i, j = index(v[0], source, line), index(v[1], source, line)
    kind = EdgeKind.ODOMETRY if j == i + 1 else EdgeKind.LOOP
    if tag == "EDGE_SE2":
        relative = from_se2(v[2], v[3], v[4])
        information = lift_information(tuple(v[5:11]))
    elif tag == LANDMARK_EDGE:
        relative = (v[2], v[3], 0.0, 0.0, 0.0, 0.0, 1.0)
        information = lift_information(tuple(v[4:7]), XY_AXES)
        kind = EdgeKind.LANDMARK
    else:
        relative = _quaternion((v[2], v[3], v[4], v[5], v[6], v[7], v[8]), source, line)
        information = tuple(v[9:30])
    return GraphEdge((mission, i), (mission, j), relative, information, kind, origin)


def vertex_values(index: int, pose: Pose, planar: bool) -> Record:
    """The record of a vertex (2D when `planar`)."""
    if planar:
        return "VERTEX_SE2", [index, pose[0], pose[1], yaw(pose)]
    return "VERTEX_SE3:QUAT", [index, *pose]


def landmark_values(index: int, point: Point) -> Record:
    """The record of a landmark (2D only: g2o's `VERTEX_XY`)."""
    return LANDMARK_VERTEX, [index, point[0], point[1]]


def edge_values(edge: GraphEdge, planar: bool) -> Record:
    """The record of an edge (2D when `planar`; a landmark observation is 2D)."""
    ends, rel = [edge.source[1], edge.target[1]], edge.relative
    if edge.kind is EdgeKind.LANDMARK:
        return LANDMARK_EDGE, [
            *ends,
            rel[0],
            rel[1],
            *project_information(edge.information, XY_AXES),
        ]
    if planar:
        info = project_information(edge.information)
        return "EDGE_SE2", [*ends, rel[0], rel[1], yaw(rel), *info]
    return "EDGE_SE3:QUAT", [*ends, *rel, *edge.information]


def lean_origin(origin: Origin, tag: str, values: Sequence[float]) -> Origin:
    """`origin` without its text when its number formatting (`Origin.digits`)
    writes `values` after `tag` as exactly that text (the row then holds its
    numbers once; an edge's text was 40 % of its row), else `origin`."""
    digits = _digits(origin.text)
    lean = Origin(origin.line, "", digits or b"")
    if digits is None or written(lean, tag, values) != origin.text:
        return origin
    return lean


def lean_vertex(index: int, pose: Pose, origin: Origin, planar: bool) -> Origin:
    """The vertex's `origin` for its row (`lean_origin`); `planar` as imported."""
    return lean_origin(origin, *vertex_values(index, pose, planar))


def lean_landmark(index: int, point: Point, origin: Origin) -> Origin:
    """The landmark's `origin` for its row (`lean_origin`)."""
    return lean_origin(origin, *landmark_values(index, point))


def lean_edge(edge: GraphEdge, planar: bool) -> GraphEdge:
    """The edge with the origin for its row (`lean_origin`); `planar` as imported."""
    lean = lean_origin(edge.origin, *edge_values(edge, planar))
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


def _fixed(value: float, decimals: int) -> str:
    # an int through "f" goes through a float, which loses a 64-bit key's low bits
    if isinstance(value, int) and not decimals:
        return str(value)
    return f"{value:.{decimals}f}"


def written(origin: Origin, tag: str, values: Sequence[float]) -> str | None:
    """The record's text as read: kept, or written again from `values` with its
    formatting; None when there is neither (or the formatting is for other values)."""
    if origin.text:
        return origin.text
    if not origin.digits or len(origin.digits) != len(values):
        return None
    return " ".join([tag, *(_fixed(v, d) for v, d in zip(values, origin.digits, strict=True))])


def vertex_line(index: int, pose: Pose, origin: Origin, planar: bool) -> str:
    """The vertex's text as read while it still says `index` and `pose`, else
    the line its values give."""
    tag, values = vertex_values(index, pose, planar)
    text = written(origin, tag, values)
    read = _reread(text, tag)
    if text and read is not None and read[1][0] == index and vertex_pose(*read, "", 0) == pose:
        return text
    return _plain(tag, values)


def landmark_line(index: int, point: Point, origin: Origin) -> str:
    """The landmark's text as read while it still says `index` and `point`,
    else the line its values give."""
    tag, values = landmark_values(index, point)
    text = written(origin, tag, values)
    read = _reread(text, tag)
    if text and read is not None and read[1][0] == index and landmark_point(read[1]) == point:
        return text
    return _plain(tag, values)


def edge_line(edge: GraphEdge, planar: bool) -> str:
    """The edge's text as read while it still says what the edge holds, else
    the line its values give."""
    tag, values = edge_values(edge, planar)
    text = written(edge.origin, tag, values)
    read = _reread(text, tag)
    if text and read is not None:
        again = edge_of(edge.source[0], *read, "", 0)
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


def _reread(text: str | None, tag: str) -> Record | None:
    """(tag, values) of a record's text as read, when it is a `tag` record;
    None when there is none (or it no longer parses, which a stored row never should)."""
    if not text:
        return None
    try:
        read = parse_record(text, "", 0)
    except (MapImportError, ValueError):
        return None
    if read is None or read[0] != tag:
        return None
    return read
