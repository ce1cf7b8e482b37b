"""The map tables and the conversion between `MissionGraph` parts and their
protobuf messages (`proto/mapapi/v1/maps.proto`).

Importing this module registers the `mapapi.v1` map types in the default
protobuf pool, so `TableDescriptor.named(..., "mapapi.v1.Vertex")` finds them.
"""

from __future__ import annotations

import math
from typing import Protocol

from google.protobuf.message import Message

from mapapi._pb.mapapi.v1 import maps_pb2
from mapapi.lookup.spatial import BBox
from mapapi.maps.graph import NO_ORIGIN, EdgeKind, GraphEdge, Origin, Point
from mapapi.maps.se3 import Pose

MISSIONS, VERTICES, EDGES, LANDMARKS, CLOUDS, FRAMES, GRIDS = (
    "missions",
    "vertices",
    "edges",
    "landmarks",
    "pointclouds",
    "frames",
    "grids",
)

Mission = maps_pb2.Mission
TilePb = maps_pb2.Tile
Vertex = maps_pb2.Vertex
Edge = maps_pb2.Edge
Landmark = maps_pb2.Landmark
PointCloudBlock = maps_pb2.PointCloudBlock
Box3 = maps_pb2.Box3
Pose3 = maps_pb2.Pose3
OriginPb = maps_pb2.Origin
Frame = maps_pb2.Frame
GridTile = maps_pb2.GridTile

# table name -> payload class, for the tables a graph (or a cloud) import writes; a
# graph's import makes its (empty) frames chunk, where `mapctl align` writes
GRAPH_TABLES: dict[str, type[Message]] = {
    MISSIONS: Mission,
    VERTICES: Vertex,
    EDGES: Edge,
    FRAMES: Frame,
}
CLOUD_TABLES: dict[str, type[Message]] = {MISSIONS: Mission, CLOUDS: PointCloudBlock}
# a grid's import makes its frames chunk too, where its place in the world goes
GRID_TABLES: dict[str, type[Message]] = {MISSIONS: Mission, GRIDS: GridTile, FRAMES: Frame}
LASER_TABLES: dict[str, type[Message]] = {**GRAPH_TABLES, CLOUDS: PointCloudBlock}
MAP_TABLES: dict[str, type[Message]] = {
    **GRAPH_TABLES,
    LANDMARKS: Landmark,
    CLOUDS: PointCloudBlock,
}
_KIND = {kind: Edge.Kind.Value(kind.name) for kind in EdgeKind}


def box_to_pb(box: BBox) -> maps_pb2.Box3:
    """A `BBox` as its message."""
    return Box3(
        xmin=box.xmin, ymin=box.ymin, zmin=box.zmin, xmax=box.xmax, ymax=box.ymax, zmax=box.zmax
    )


def box_from_pb(box: maps_pb2.Box3) -> BBox:
    """A `Box3` message as a `BBox` (raises InvalidBBox when inverted)."""
    return BBox(box.xmin, box.ymin, box.zmin, box.xmax, box.ymax, box.zmax)


def pose_to_pb(p: Pose) -> maps_pb2.Pose3:
    """A pose 7-tuple as its message."""
    return Pose3(x=p[0], y=p[1], z=p[2], qx=p[3], qy=p[4], qz=p[5], qw=p[6])


def pose_from_pb(p: maps_pb2.Pose3) -> Pose:
    """A `Pose3` message as a 7-tuple."""
    return (p.x, p.y, p.z, p.qx, p.qy, p.qz, p.qw)


class MissionSource(Protocol):
    """What a mission row is made of: a `MissionGraph` or a `PointCloud`."""

    name: str
    robot: str
    frame: str

    def bbox(self) -> BBox | None:
        """The box around its vertices or points."""


def mission_to_pb(source: MissionSource) -> maps_pb2.Mission:
    """The mission row of a graph or cloud, with the box around its vertices or points."""
    message = Mission(name=source.name, robot=source.robot, frame=source.frame)
    box = source.bbox()
    if box is not None:
        message.bbox.CopyFrom(box_to_pb(box))
    return message


def origin_to_pb(origin: Origin) -> maps_pb2.Origin | None:
    """An `Origin` as its message; None for no origin (the field stays unset)."""
    if origin == NO_ORIGIN:
        return None
    return OriginPb(line=origin.line, text=origin.text, digits=origin.digits)


def origin_from_pb(message: maps_pb2.Origin) -> Origin:
    """An `Origin` message as an `Origin`."""
    return Origin(message.line, message.text, message.digits)


def vertex_to_pb(
    mission: str, index: int, pose: Pose, origin: Origin = NO_ORIGIN, timestamp: float = 0.0
) -> maps_pb2.Vertex:
    """One vertex row, with where an import read it and when the pose was taken
    (seconds; 0: unknown)."""
    return Vertex(
        mission=mission,
        index=index,
        pose=pose_to_pb(pose),
        timestamp=timestamp,
        origin=origin_to_pb(origin),
    )


def landmark_to_pb(
    mission: str, index: int, point: Point, origin: Origin = NO_ORIGIN
) -> maps_pb2.Landmark:
    """One landmark row, with where an import read it."""
    position = maps_pb2.Point3(x=point[0], y=point[1], z=point[2])
    return Landmark(mission=mission, index=index, position=position, origin=origin_to_pb(origin))


def landmark_from_pb(message: maps_pb2.Landmark) -> Point:
    """A landmark row's position."""
    p = message.position
    return (p.x, p.y, p.z)


INFORMATION_SIZE = 21
"""Values of a 6x6 information matrix's upper triangle."""

SPARSE_AT_MOST = 16
"""Non-zero entries up to which an edge stores its information sparsely (each
costs a position byte more; 21 dense values cost 168 bytes)."""


def edge_to_pb(mission: str, edge: GraphEdge) -> maps_pb2.Edge:
    """One edge row, owned by `mission`: its ends in `mission` name no mission,
    and an information matrix of few non-zero entries keeps only those."""
    message = Edge(mission=mission, relative=pose_to_pb(edge.relative), kind=_KIND[edge.kind])
    for ref, (end_mission, index) in (
        (message.from_vertex, edge.source),
        (message.to_vertex, edge.target),
    ):
        ref.index = index
        if end_mission != mission:
            ref.mission = end_mission
    at = [k for k, v in enumerate(edge.information) if not _plain_zero(v)]
    if len(edge.information) == INFORMATION_SIZE and 0 < len(at) <= SPARSE_AT_MOST:
        message.information_at.extend(at)
        message.information.extend(edge.information[k] for k in at)
    else:
        message.information.extend(edge.information)
    origin = origin_to_pb(edge.origin)
    if origin is not None:
        message.origin.CopyFrom(origin)
    return message


def _plain_zero(value: float) -> bool:
    """0.0 (not -0.0, which a sparse matrix would give back as 0.0)."""
    return value == 0.0 and math.copysign(1.0, value) > 0


def edge_ends(message: maps_pb2.Edge) -> tuple[tuple[str, int], tuple[str, int]]:
    """The (mission, index) of an edge row's two ends."""
    own = message.mission
    return (
        (message.from_vertex.mission or own, message.from_vertex.index),
        (message.to_vertex.mission or own, message.to_vertex.index),
    )


def edge_information(message: maps_pb2.Edge) -> tuple[float, ...]:
    """An edge row's 21 information values (however it stores them)."""
    if not message.information_at:
        return tuple(message.information)
    full = [0.0] * INFORMATION_SIZE
    for k, value in zip(message.information_at, message.information, strict=True):
        full[k] = value
    return tuple(full)


def edge_from_pb(message: maps_pb2.Edge) -> GraphEdge:
    """A stored edge row as a `GraphEdge`."""
    source, target = edge_ends(message)
    return GraphEdge(
        source,
        target,
        pose_from_pb(message.relative),
        edge_information(message),
        EdgeKind(message.kind),
        origin_from_pb(message.origin),
    )
