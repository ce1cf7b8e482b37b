"""What `mapctl bench spatial` registers of each mission: its row's box, and the
spatial tiles an import would cut it into (`mapapi.maps.tiles`), each with the
rows and bytes a `query-bbox --load` of it moves: its vertices and its edges,
encoded as an import encodes them (`mapapi.maps.rows.build_rows`)."""

from __future__ import annotations

import hashlib
import math
import random
from collections.abc import Mapping, Set
from dataclasses import dataclass, replace

from mapapi.core.ids import ChunkId
from mapapi.lookup.spatial import BBox
from mapapi.maps.graph import MissionGraph
from mapapi.maps.rows import build_rows
from mapapi.maps.schema import EDGES, MISSIONS, VERTICES
from mapapi.maps.tiles import tile_graph


@dataclass(frozen=True)
class TilePart:
    """One tile of a mission: its box, and the rows (vertices and edges) and
    payload bytes loading it moves."""

    mission: str
    number: int
    bbox: BBox
    rows: int
    bytes: int

    @property
    def chunk(self) -> ChunkId:
        """The id it is registered under."""
        return stable_chunk(f"{self.mission}#{self.number}")


def stable_chunk(name: str) -> ChunkId:
    """A stable id: the same mission or tile is the same chunk in every grid and run."""
    return ChunkId(hashlib.md5(name.encode(), usedforsecurity=False).hexdigest())


@dataclass(frozen=True)
class MissionPart:
    """One mission: its box, its row's bytes, and its tiles."""

    name: str
    bbox: BBox
    row_bytes: int
    tiles: tuple[TilePart, ...]
    points: tuple[tuple[float, float, float], ...] = ()  # its vertices' positions

    @property
    def chunk(self) -> ChunkId:
        """The id its row is registered under."""
        return stable_chunk(self.name)

    @property
    def rows(self) -> int:
        """Every row of the mission: its own and its tiles'."""
        return 1 + sum(t.rows for t in self.tiles)

    @property
    def bytes(self) -> int:
        """The payload bytes of every row of the mission."""
        return self.row_bytes + sum(t.bytes for t in self.tiles)


def mission_part(graph: MissionGraph) -> MissionPart | None:
    """`graph` as the bench registers it (None: it has no vertices)."""
    box = graph.bbox()
    if box is None:
        return None
    rows = build_rows(graph)
    vertex_bytes = [m.ByteSize() for m in rows[VERTICES]]  # in `graph.vertices` order
    at = {index: n for n, index in enumerate(graph.vertices)}
    edge_bytes = [m.ByteSize() for m in rows[EDGES]]
    tiles = tuple(
        TilePart(
            graph.name,
            number,
            tile.bbox,
            len(tile.vertices) + len(tile.edges),
            sum(vertex_bytes[at[i]] for i in tile.vertices)
            + sum(edge_bytes[n] for n in tile.edges),
        )
        for number, tile in enumerate(tile_graph(graph))
    )
    points = tuple((p[0], p[1], p[2]) for p in graph.vertices.values())
    return MissionPart(graph.name, box, rows[MISSIONS][0].ByteSize(), tiles, points)


def pose_boxes(
    parts: Mapping[str, MissionPart],
    extent: BBox,
    vertical: int,
    count: int,
    share: float,
    seed: int,
) -> list[BBox]:
    """`count` seeded boxes, each the smallest square (over the horizontal axes,
    all of `extent` along the `vertical` one) around a random pose that holds
    `share` of all the poses: boxes that hold a given part of the map, however
    unevenly its poses spread."""
    import numpy as np  # only this bench needs it here

    points = np.array([p for part in parts.values() for p in part.points])
    across = [axis for axis in range(3) if axis != vertical]
    rng = random.Random(f"{seed}:poses")
    wanted = max(1, math.ceil(share * len(points)))
    boxes = []
    for _ in range(count):
        centre = points[rng.randrange(len(points))]
        reach = np.max(np.abs(points[:, across] - centre[across]), axis=1)
        half = float(np.partition(reach, wanted - 1)[wanted - 1])
        lows, highs = list(extent.mins), list(extent.maxs)
        for axis in across:
            lows[axis], highs[axis] = centre[axis] - half, centre[axis] + half
        boxes.append(BBox(*lows, *highs))
    return boxes


@dataclass(frozen=True)
class Moved:
    """What a `query-bbox --load` of one query's findings moves: the rows of the
    missions found and of the tiles found, against the whole missions found."""

    missions: set[str]
    tiles: int
    rows: int
    bytes: int
    rows_whole: int
    bytes_whole: int

    @classmethod
    def of(cls, parts: Mapping[str, MissionPart], found: Set[ChunkId]) -> Moved:
        """What loading the chunks `found` (rows and tiles) of `parts` moves."""
        whole = [part for part in parts.values() if part.chunk in found]
        hit = [tile for part in parts.values() for tile in part.tiles if tile.chunk in found]
        return cls(
            {part.name for part in whole},
            len(hit),
            len(whole) + sum(t.rows for t in hit),
            sum(p.row_bytes for p in whole) + sum(t.bytes for t in hit),
            sum(p.rows for p in whole),
            sum(p.bytes for p in whole),
        )

    @property
    def share(self) -> float:
        """The rows moved as a share of the whole missions' (0 when none was found)."""
        return round(self.rows / self.rows_whole, 4) if self.rows_whole else 0.0


def segments(graph: MissionGraph, size: int) -> list[MissionGraph]:
    """`graph`'s vertices, in index order, cut into missions of `size` vertices
    (the last may be shorter), named ``{graph.name}-{k:02d}``, each with the
    edges among its own vertices (edges between segments are dropped).

    Raises:
        ValueError: `size` is below 1.
    """
    if size < 1:
        raise ValueError(f"a segment holds at least 1 vertex, got {size}")
    order = sorted(graph.vertices)
    cut = []
    for k, start in enumerate(range(0, len(order), size)):
        name = f"{graph.name}-{k:02d}"
        vertices = {i: graph.vertices[i] for i in order[start : start + size]}
        edges = [
            replace(e, source=(name, e.source[1]), target=(name, e.target[1]))
            for e in graph.edges
            if e.source[1] in vertices and e.target[1] in vertices
        ]
        cut.append(MissionGraph(name, graph.robot, graph.frame, vertices, edges))
    return cut
