"""GTSAM's 2D landmark SLAM text (`victoria_park.txt`): a streaming reader (pure).

One record per line (`shared/datasets/README.md` §5), as GTSAM's `load2D` reads it:

- `ODOMETRY i j dx dy dtheta c_xx c_xy c_xt c_yy c_yt c_tt`: the pose of `j` in
  `i`'s frame, with the upper triangle of its **covariance** (not information).
  It is odometry whatever the ids: they skip the landmarks' (`ODOMETRY 4 6`).
- `LANDMARK i l lx ly c_xx c_xy c_yy`: landmark `l` seen from pose `i` at
  (lx, ly) in the pose's frame, with its covariance. GTSAM turns this into a
  bearing and a range with a noise it makes up ("assume it describes the
  uncertainty at a range of 10m"); we keep what the file says, a relative
  position and its covariance, as a `LANDMARK` edge: nothing is lost, and a
  solver can form either factor from it.

Landmark ids are GTSAM keys like the poses' (Victoria Park numbers both in one
sequence), but nothing requires it: they are a namespace of their own here,
and a g2o export moves them past the poses' when they collide
(`g2o.landmark_shift`). The file holds no poses and
no landmark positions: poses are chained from the odometry from the identity,
and each landmark starts where its first observation puts it, seen from that
pose (`graph.place_landmarks`). Covariances are inverted into the information
the edge table holds; one that is not positive definite is refused, naming its
line. The graph is planar; `export` writes it as g2o (`VERTEX_XY`, `EDGE_SE2_XY`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from pathlib import Path

from mapapi.maps.errors import MapImportError
from mapapi.maps.graph import (
    EdgeKind,
    GraphEdge,
    MissionGraph,
    Origin,
    chain_odometry,
    place_landmarks,
)
from mapapi.maps.se3 import XY_AXES, from_se2, invert_upper, lift_information
from mapapi.maps.text_file import check_arity

Progress = Callable[[int, int], None]  # (lines read, 0 while the total is unknown)

FORMAT = "gtsam-landmarks"
_ARITY = {"ODOMETRY": 11, "LANDMARK": 7}  # values after the tag
_PROGRESS_EVERY = 10_000


def looks_like(path: Path) -> bool:
    """True when the first record of `path` is an `ODOMETRY` or `LANDMARK` line
    (the extension, `.txt`, says nothing)."""
    if not path.is_file():
        return False
    with path.open(encoding="utf-8", errors="replace") as lines:
        for line in lines:
            parts = line.split()
            if parts and not parts[0].startswith("#"):
                return parts[0] in _ARITY
    return False


def parse_gtsam_landmarks(
    lines: Iterable[str],
    mission: str,
    robot: str = "",
    *,
    source: str = "",
    progress: Progress | None = None,
) -> MissionGraph:
    """Parse GTSAM landmark text line by line into a planar `MissionGraph`
    (`text_file.read_text(parse_gtsam_landmarks, path)` reads a file).

    Args:
        lines: the text (an open file streams).
        source: the file name errors mention.
        progress: called every 10,000 lines with (lines read, 0).

    Raises:
        MapImportError: an unknown record, a wrong number of values, a value
            that is not a finite number, an id that is not natural, a covariance
            that is not positive definite, or no odometry at all.
    """
    graph = MissionGraph(mission, robot, frame=f"{mission}/map", planar=True)
    number = 0
    for number, line in enumerate(lines, 1):
        parts = line.split()
        if parts and not parts[0].startswith("#"):
            graph.edges.append(_edge(mission, parts, source, number))
        if progress is not None and number % _PROGRESS_EVERY == 0:
            progress(number, 0)
    poses = {e.source[1] for e in graph.edges}
    poses |= {e.target[1] for e in graph.edges if e.kind is not EdgeKind.LANDMARK}
    if not poses:
        raise MapImportError("no ODOMETRY or LANDMARK records", source=source)
    chain_odometry(graph, poses)
    place_landmarks(graph)
    if progress is not None:
        progress(number, number)
    return graph


def _edge(mission: str, parts: list[str], source: str, line: int) -> GraphEdge:
    tag = check_arity(parts, _ARITY, source, line)
    try:
        i, j = int(parts[1]), int(parts[2])
        v = [float(p) for p in parts[3:]]
        if min(i, j) < 0 or not math.isfinite(math.fsum(v)):
            raise ValueError("ids must be natural numbers and values finite")
        if tag == "ODOMETRY":
            relative = from_se2(v[0], v[1], v[2])
            information = lift_information(invert_upper(tuple(v[3:9])))
            kind = EdgeKind.ODOMETRY  # the tag says so; ids skip the landmarks' (`4 -> 6`)
        else:
            relative = (v[0], v[1], 0.0, 0.0, 0.0, 0.0, 1.0)
            information = lift_information(invert_upper(tuple(v[2:5])), XY_AXES)
            kind = EdgeKind.LANDMARK
    except ValueError as exc:
        raise MapImportError(f"{tag}: {exc}", source=source, line=line) from None
    return GraphEdge((mission, i), (mission, j), relative, information, kind, Origin(line))
