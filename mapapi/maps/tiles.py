"""Spatial tiles: how an import cuts a mission's pose graph into chunks of bounded
extent and size (issue 14 §3), so a box query loads what lies in the box and not
the whole mission.

The vertices are split as a k-d tree: a set of vertices larger than `max_vertices`,
or wider than `max_extent` metres on some axis and larger than `min_vertices`, is
cut in two at the median of its widest axis, and each half is split again. Each
leaf is a tile; its box is the box around its vertices, so tiles of one mission
never overlap (except on a cut where several vertices share the median's
coordinate). The split depends only on
the positions and indices, so importing one graph twice tiles it the same way.
Vertices at one spot are still cut by count (by index), so no tile is larger
than `max_vertices`, though their boxes then coincide.

**The edge rule.** An edge belongs to the tile of its source vertex when that
vertex is in the mission, else to the tile of its target. Loading a box loads every
tile whose box overlaps it, and a vertex in the box lies in such a tile; so an
edge whose ends both lie in the box is loaded with its source's tile. An edge that
names no vertex of its mission at all (never written by an import: `check_graph`
refuses it) goes to the first tile.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from mapapi.core.ids import ChunkId
from mapapi.lookup.spatial import BBox
from mapapi.maps.graph import GraphEdge, MissionGraph
from mapapi.maps.schema import TilePb, box_from_pb, box_to_pb
from mapapi.maps.se3 import Pose

TILE_VERTICES = 768
"""Most vertices in one tile: a tile's rows (about twice that, with its edges)
travel as one snapshot, so this bounds what a load holds in memory at once."""

TILE_EXTENT = 64.0
"""Widest a tile of more than `TILE_MIN_VERTICES` may be on any axis, in metres: the
default spatial grid's cell (`mapapi.lookup.spatial`), so such a tile is registered
in at most 4 cells of a plane."""

TILE_MIN_VERTICES = 192
"""Fewest vertices a tile is cut down to for its extent: each chunk is a Raft group
of its own, and a sparse robot path of 150 poses over 500 m cut every 64 m made
tiles of 20 poses."""


@dataclass(frozen=True)
class Tile:
    """One tile of a mission: its vertices (by index), its edges (by position in
    the mission's edge list) and the box around its vertices."""

    vertices: tuple[int, ...]
    edges: tuple[int, ...]
    bbox: BBox


@dataclass(frozen=True)
class TileChunks:
    """Where one tile of a stored mission is: the chunk of its vertices and the
    chunk of its edges (None: it has none), as its mission row lists them."""

    vertices: ChunkId
    edges: ChunkId | None
    bbox: BBox
    vertex_count: int
    edge_count: int

    def to_pb(self) -> Any:
        """The tile as its `mapapi.v1.Tile` message."""
        return TilePb(
            bbox=box_to_pb(self.bbox),
            vertices=self.vertices,
            edges=self.edges or "",
            vertex_count=self.vertex_count,
            edge_count=self.edge_count,
        )

    @classmethod
    def from_pb(cls, message: Any) -> TileChunks:
        """A `mapapi.v1.Tile` message as read from a mission row.

        Raises:
            ValueError: it names no valid chunk or box (a row not written by an import).
        """
        edges = ChunkId(message.edges) if message.edges else None
        return cls(
            ChunkId(message.vertices),
            edges,
            box_from_pb(message.bbox),
            message.vertex_count,
            message.edge_count,
        )

    def chunks(self) -> list[ChunkId]:
        """Its chunks."""
        return [self.vertices] if self.edges is None else [self.vertices, self.edges]


def tile_graph(
    graph: MissionGraph,
    max_vertices: int = TILE_VERTICES,
    max_extent: float = TILE_EXTENT,
    min_vertices: int = TILE_MIN_VERTICES,
) -> list[Tile]:
    """The tiles of `graph` (see the module docstring), in k-d order; none for a
    graph without vertices (an import refuses it).

    Raises:
        ValueError: `max_vertices` < 1 or `max_extent` <= 0.
    """
    if max_vertices < 1 or not max_extent > 0:
        raise ValueError(
            f"tiles need max_vertices >= 1 and max_extent > 0, got {max_vertices} and {max_extent}"
        )
    if not graph.vertices:
        return []
    bounds = (max_vertices, max_extent, min_vertices)
    leaves = _split(sorted(graph.vertices), graph.vertices, *bounds)
    tile_of = {index: n for n, leaf in enumerate(leaves) for index in leaf}
    edges: list[list[int]] = [[] for _ in leaves]
    for position, edge in enumerate(graph.edges):
        edges[_edge_tile(graph.name, edge, tile_of)].append(position)
    return [
        Tile(tuple(leaf), tuple(owned), _box(leaf, graph.vertices))
        for leaf, owned in zip(leaves, edges, strict=True)
    ]


def _edge_tile(mission: str, edge: GraphEdge, tile_of: Mapping[int, int]) -> int:
    for end in (edge.source, edge.target):
        if end[0] == mission and end[1] in tile_of:
            return tile_of[end[1]]
    return 0


def _split(
    indices: list[int],
    poses: Mapping[int, Pose],
    max_vertices: int,
    max_extent: float,
    min_vertices: int,
) -> list[list[int]]:
    """The leaves of the k-d split of `indices`, iteratively (a long corridor
    would recurse once per cut)."""
    leaves: list[list[int]] = []
    todo = [indices]
    while todo:
        part = todo.pop()
        axis, width = _widest(part, poses)
        small = len(part) <= min_vertices or width <= max_extent
        if len(part) <= 1 or (len(part) <= max_vertices and small):
            leaves.append(part)
            continue
        part.sort(key=lambda i: (poses[i][axis], i))
        middle = len(part) // 2
        todo += [part[middle:], part[:middle]]  # the lower half is taken first
    return leaves


def _widest(part: Sequence[int], poses: Mapping[int, Pose]) -> tuple[int, float]:
    """The axis along which `part`'s positions spread most, and that spread."""
    spans = []
    for axis in range(3):
        values = [poses[i][axis] for i in part]
        spans.append(max(values) - min(values))
    width = max(spans)
    return spans.index(width), width


def _box(indices: Sequence[int], poses: Mapping[int, Pose]) -> BBox:
    xs, ys, zs = (tuple(poses[i][axis] for i in indices) for axis in range(3))
    return BBox(min(xs), min(ys), min(zs), max(xs), max(ys), max(zs))
