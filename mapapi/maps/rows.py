"""A mission's rows: the protobuf messages an import writes for a pose graph or a
point cloud, each checked first (`mapapi.maps.importer` stages them)."""

from __future__ import annotations

from collections.abc import Sequence

from google.protobuf.message import Message

from mapapi.maps.cloud import PointCloud, cloud_blocks
from mapapi.maps.errors import MapImportError
from mapapi.maps.g2o_records import lean_edge, lean_landmark, lean_vertex
from mapapi.maps.graph import NO_ORIGIN, EdgeKind, MissionGraph
from mapapi.maps.schema import (
    CLOUDS,
    EDGES,
    LANDMARKS,
    MISSIONS,
    VERTICES,
    edge_to_pb,
    landmark_to_pb,
    mission_to_pb,
    vertex_to_pb,
)


def check_graph(graph: MissionGraph) -> None:
    """Refuse a graph an import cannot store.

    Raises:
        MapImportError: no name, no vertices, an edge names a vertex the mission
            lacks, or a landmark observation a landmark it lacks.
    """
    if not graph.name:
        raise MapImportError("a mission needs a name")
    if not graph.vertices:
        raise MapImportError("the graph has no vertices", source=graph.name)
    name = graph.name
    for edge in graph.edges:
        landmark = edge.kind is EdgeKind.LANDMARK
        if landmark and (edge.target[0] != name or edge.target[1] not in graph.landmarks):
            raise MapImportError(
                f"an edge observes the missing landmark {edge.target}", source=name
            )
        for end in (edge.source,) if landmark else (edge.source, edge.target):
            if end[0] == name and end[1] not in graph.vertices:
                raise MapImportError(f"an edge names the missing vertex {end[1]}", source=name)


def build_rows(graph: MissionGraph) -> dict[str, list[Message]]:
    """Every row of a mission, by table, checked (`check_graph`).

    Raises:
        MapImportError: the graph is not importable.
    """
    check_graph(graph)
    return {
        MISSIONS: [mission_to_pb(graph)],
        VERTICES: vertex_rows(graph, list(graph.vertices)),
        LANDMARKS: landmark_rows(graph),
        EDGES: edge_rows(graph, range(len(graph.edges))),
    }


def build_cloud_rows(cloud: PointCloud) -> dict[str, list[Message]]:
    """The mission row and the point blocks of a cloud.

    Raises:
        MapImportError: no name, or no points.
    """
    if not cloud.name:
        raise MapImportError("a mission needs a name")
    if len(cloud.points) == 0:
        raise MapImportError("the cloud has no points", source=cloud.name)
    return {MISSIONS: [mission_to_pb(cloud)], CLOUDS: list(cloud_blocks(cloud))}


def vertex_rows(graph: MissionGraph, indices: Sequence[int]) -> list[Message]:
    """The rows of the vertices `indices`, with where the import read each and
    when its pose was taken."""
    origins, poses, planar, stamps = graph.origins, graph.vertices, graph.planar, graph.timestamps
    return [
        vertex_to_pb(
            graph.name,
            i,
            poses[i],
            lean_vertex(i, poses[i], origins.get(i, NO_ORIGIN), planar),
            stamps.get(i, 0.0),
        )
        for i in indices
    ]


def landmark_rows(graph: MissionGraph) -> list[Message]:
    """The rows of the mission's landmarks, with where the import read each."""
    origins = graph.landmark_origins
    return [
        landmark_to_pb(graph.name, i, p, lean_landmark(i, p, origins.get(i, NO_ORIGIN)))
        for i, p in graph.landmarks.items()
    ]


def edge_rows(graph: MissionGraph, positions: Sequence[int]) -> list[Message]:
    """The rows of the edges at `positions` of the graph's edge list."""
    return [edge_to_pb(graph.name, lean_edge(graph.edges[n], graph.planar)) for n in positions]
