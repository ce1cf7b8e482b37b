"""The in-memory pose graph the parsers build and `import_graph` stores.

A `MissionGraph` is one robot's session: its vertices (index -> pose), its
landmarks (index -> position, an index space of their own) and the edges it
owns. An edge's ends are `(mission, index)` pairs, so an inter-robot edge names
a vertex of another mission; a landmark observation (`EdgeKind.LANDMARK`) goes
from a vertex to a landmark.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable
from dataclasses import dataclass, field
from enum import Enum

from mapapi.lookup.spatial import BBox
from mapapi.maps.errors import MapImportError
from mapapi.maps.se3 import IDENTITY, Pose, compose

log = logging.getLogger(__name__)

VertexKey = tuple[str, int]  # (mission, index)
Point = tuple[float, float, float]


@dataclass(frozen=True, slots=True)
class Origin:
    """Where an import read a vertex or edge (`mapapi.v1.Origin`), so export can
    write the mission back in its order and with its number formatting.

    Attributes:
        line: the record's line in its file (1-based), 0 when it had none.
        text: the record's g2o text as read, without the line break ("" if none,
            or when `digits` give it back).
        digits: the decimals of each number of that text, when the text is its
            tag and the row's values written with them (`g2o_records.lean_origin`).
    """

    line: int = 0
    text: str = ""
    digits: bytes = b""


NO_ORIGIN = Origin()


class EdgeKind(Enum):
    """What an edge measures (values match `mapapi.v1.Edge.Kind`)."""

    ODOMETRY = 1
    LOOP = 2
    INTER_ROBOT = 3
    LANDMARK = 4


@dataclass(frozen=True, slots=True)
class GraphEdge:
    """A relative pose measurement `source -> target`, in the source's frame;
    for a `LANDMARK` edge, the position of the landmark `target` (its rotation
    is the identity).

    Attributes:
        information: the 21-value upper triangle of the 6x6 information matrix,
            row-major over (x, y, z, rx, ry, rz) (a landmark's: on x, y, z only).
    """

    source: VertexKey
    target: VertexKey
    relative: Pose
    information: tuple[float, ...]
    kind: EdgeKind
    origin: Origin = NO_ORIGIN


@dataclass(slots=True)
class MissionGraph:
    """One mission's pose graph.

    Attributes:
        name: the mission's name, unique in a repository.
        robot: the robot that recorded it.
        frame: the frame its poses are in.
        vertices: vertex index -> pose (initial estimate).
        edges: the edges this mission owns (inter-robot ones included).
        planar: True when it came from a 2D (SE2) source.
        origins: vertex index -> where the import read it (absent: nowhere).
        timestamps: vertex index -> when the pose was taken, in seconds (absent:
            the source has no time, as g2o and Kimera CSV files have not).
        landmarks: landmark index -> position (initial estimate).
        landmark_origins: landmark index -> where the import read it.
    """

    name: str
    robot: str = ""
    frame: str = ""
    vertices: dict[int, Pose] = field(default_factory=dict)
    edges: list[GraphEdge] = field(default_factory=list)
    planar: bool = False
    origins: dict[int, Origin] = field(default_factory=dict)
    timestamps: dict[int, float] = field(default_factory=dict)
    landmarks: dict[int, Point] = field(default_factory=dict)
    landmark_origins: dict[int, Origin] = field(default_factory=dict)

    def bbox(self) -> BBox | None:
        """The box around the vertex and landmark positions (None without vertices)."""
        if not self.vertices:
            return None
        points = [p[:3] for p in self.vertices.values()] + list(self.landmarks.values())
        xs, ys, zs = zip(*points, strict=True)
        return BBox(min(xs), min(ys), min(zs), max(xs), max(ys), max(zs))

    def count(self, kind: EdgeKind) -> int:
        """How many edges of `kind` this mission owns."""
        return sum(1 for e in self.edges if e.kind is kind)

    def elements(self) -> int:
        """Vertices, landmarks and edges: the unit of the import speed target."""
        return len(self.vertices) + len(self.landmarks) + len(self.edges)


def place_landmarks(graph: MissionGraph) -> int:
    """Give every landmark an observation names but the source did not place a
    position: where its first observation (in edge order) puts it, seen from
    that observation's pose (a range-bearing or relative-position file holds no
    landmark positions; a solver refines this start). Returns how many were placed.

    Raises:
        MapImportError: an observation's pose is not a vertex of the mission.
    """
    placed = 0
    for edge in graph.edges:
        index = edge.target[1]
        if edge.kind is not EdgeKind.LANDMARK or index in graph.landmarks:
            continue
        pose = graph.vertices.get(edge.source[1]) if edge.source[0] == graph.name else None
        if pose is None:
            raise MapImportError(
                f"landmark {index} is observed from {edge.source}, which is not a pose here",
                source=graph.name,
                line=edge.origin.line,
            )
        x, y, z = compose(pose, edge.relative)[:3]
        graph.landmarks[index] = (x, y, z)
        placed += 1
    return placed


def chain_odometry(graph: MissionGraph, wanted: Iterable[int]) -> int:
    """Give every index in `wanted` without a pose one, by chaining the
    mission's odometry edges (i -> i+1) from the lowest index, which starts at
    the identity. A vertex the chain cannot reach starts again at the identity
    (logged). Returns how many vertices were added.

    Raises:
        MapImportError: two odometry edges lead to the same vertex.
    """
    odometry: dict[int, GraphEdge] = {}
    for edge in graph.edges:
        if edge.kind is EdgeKind.ODOMETRY and edge.target[0] == graph.name:
            if edge.target[1] in odometry:
                raise MapImportError(
                    f"two odometry edges lead to vertex {edge.target[1]}", source=graph.name
                )
            odometry[edge.target[1]] = edge
    added = 0
    for index in sorted(set(wanted) - graph.vertices.keys()):
        before = odometry.get(index)
        start = None if before is None else graph.vertices.get(before.source[1])
        if start is None or before is None:
            if added:
                log.warning("mission %s: vertex %d restarts at the identity", graph.name, index)
            graph.vertices[index] = IDENTITY
        else:
            graph.vertices[index] = compose(start, before.relative)
        added += 1
    return added
