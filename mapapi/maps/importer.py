"""Store missions in a peer: one transaction per mission, all or nothing.

A pose graph gets a chunk for its mission row, one for its frames (empty until
`mapctl align`) and, per spatial tile (`mapapi.maps.tiles`), a chunk of the
tile's vertices and one of its edges (none for a tile without edges); the
mission row lists them. Its landmarks, if any, get one chunk (not tiled: a
landmark map is small next to its poses), which the mission row names; a
landmark observation is an edge of its pose's tile. A point cloud gets one
chunk for its mission row and one of point-cloud blocks; a laser mission
(`mapapi.maps.laser`), a graph's chunks and one of its scans' blocks. An
occupancy grid (`mapapi.maps.occupancy`) gets its mission row's chunk and one
of its tiles, which the mission row names. Everything is built
and checked first; chunks are created and rows staged only then, and committed
once, so a failing import leaves no rows and no chunks. `import_missions`
checks every name of a set before the first commit, so a clash stops the set
before anything of it is written.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from functools import partial
from typing import TYPE_CHECKING

from mapapi.core.ids import ChunkId, CommitId
from mapapi.lookup.spatial import BBox
from mapapi.maps.cloud import PointCloud
from mapapi.maps.errors import MapImportError
from mapapi.maps.graph import GraphEdge, MissionGraph
from mapapi.maps.laser import Correction, LaserMission, scan_blocks
from mapapi.maps.occupancy import OccupancyGrid, grid_tiles
from mapapi.maps.rows import build_cloud_rows, check_graph, edge_rows, landmark_rows, vertex_rows
from mapapi.maps.schema import (
    CLOUD_TABLES,
    CLOUDS,
    EDGES,
    FRAMES,
    GRAPH_TABLES,
    GRID_TABLES,
    GRIDS,
    LANDMARKS,
    LASER_TABLES,
    MISSIONS,
    VERTICES,
    Landmark,
    Mission,
    mission_to_pb,
)
from mapapi.maps.stored import mission_names, reading
from mapapi.maps.tiles import Tile, TileChunks, tile_graph

if TYPE_CHECKING:
    from google.protobuf.message import Message

    from mapapi.core.transaction import Transaction
    from mapapi.service.peer import Peer

log = logging.getLogger(__name__)

Progress = Callable[[int, int], None]  # (rows staged, rows in all)
MapSource = MissionGraph | PointCloud | OccupancyGrid
_PROGRESS_EVERY = 10_000


@dataclass(frozen=True)
class ImportResult:
    """What one mission's import wrote (`points` for a cloud, vertices and edges
    for a graph).

    Attributes:
        chunks: table -> chunk, for the tables of one chunk per mission (the
            mission row's, a cloud's blocks).
        tiles: a graph's tiles, each in chunks of its own.
        warnings: what the reader could not do, one line each (`PointCloud.warnings`).
        correction: how scan matching moved a laser mission's poses.
    """

    mission: str
    robot: str
    vertices: int
    edges: int
    bbox: BBox | None
    chunks: dict[str, ChunkId]
    commit: CommitId
    points: int = 0
    commit_seconds: float = 0.0  # of the import's time, what the commit itself took
    tiles: tuple[TileChunks, ...] = ()
    landmarks: int = 0
    warnings: tuple[str, ...] = ()
    correction: Correction | None = None

    def elements(self) -> int:
        """Vertices, landmarks and edges: the unit of the import speed target."""
        return self.vertices + self.landmarks + self.edges

    def all_chunks(self) -> list[ChunkId]:
        """Every chunk the import created."""
        tiled = [c for t in self.tiles for c in (t.vertices, t.edges) if c is not None]
        return [*self.chunks.values(), *tiled]


async def ensure_tables(peer: Peer, tables: Mapping[str, type[Message]] = GRAPH_TABLES) -> None:
    """Create the map tables (by default the graph tables) that do not exist yet.

    Raises:
        MapImportError: a table of that name holds another type.
    """
    existing = peer.tables()
    for name, cls in tables.items():
        wanted = cls.DESCRIPTOR.full_name
        if name in existing and existing[name].type_name != wanted:
            raise MapImportError(
                f"table {name!r} holds {existing[name].type_name}, not {wanted}; "
                "import into another repository"
            )
    for name, cls in tables.items():
        if name not in existing:
            await peer.create_table(name, cls)


def rename(graph: MissionGraph, mission: str | None, robot: str | None) -> MissionGraph:
    """The graph under another mission (and robot) name; its own edge ends follow."""
    if (mission is None or mission == graph.name) and robot is None:
        return graph
    name = mission or graph.name

    def move(edge: GraphEdge) -> GraphEdge:
        source = (name, edge.source[1]) if edge.source[0] == graph.name else edge.source
        target = (name, edge.target[1]) if edge.target[0] == graph.name else edge.target
        return replace(edge, source=source, target=target)

    return replace(
        graph,
        name=name,
        robot=graph.robot if robot is None else robot,
        frame=f"{name}/map" if mission else graph.frame,
        edges=[move(e) for e in graph.edges],
    )


@dataclass(frozen=True)
class _Part:
    """The rows of one chunk to create: of `table`, and of a tile when `tile` is set.
    `rows` builds them when they are staged, so the messages of one chunk at a time
    are alive (a 13.6k-pose mission's 27k messages took 35 MB at once)."""

    table: str
    count: int
    rows: Callable[[], list[Message]]
    tile: Tile | None = None


@dataclass(frozen=True)
class _Prepared:
    """One mission's rows, built and checked, ready to commit: the mission row
    first, then one part per chunk to create."""

    source: MapSource
    mission: Mission
    parts: list[_Part]
    tables: Mapping[str, type[Message]]
    summary: str


def _prepare(source: MapSource) -> _Prepared:
    if isinstance(source, PointCloud):
        rows = build_cloud_rows(source)
        summary = f"{len(source.points)} points in {len(rows[CLOUDS])} blocks"
        blocks = [_Part(CLOUDS, len(rows[CLOUDS]), lambda: rows[CLOUDS])]
        return _Prepared(source, rows[MISSIONS][0], blocks, CLOUD_TABLES, summary)
    if isinstance(source, OccupancyGrid):
        cut = grid_tiles(source)
        height, width = source.cells.shape
        summary = f"{width} x {height} cells of {source.resolution} m in {len(cut)} tiles"
        # its frames chunk, as a graph's (below): where its place in the world goes
        parts = [_Part(FRAMES, 0, list), _Part(GRIDS, len(cut), lambda: list(cut))]
        return _Prepared(source, mission_to_pb(source), parts, GRID_TABLES, summary)
    check_graph(source)
    tiles = tile_graph(source)
    summary = f"{len(source.vertices)} vertices, {len(source.edges)} edges in {len(tiles)} tiles"
    # The chunk of the mission's place in shared frames (`mapctl align`), made with
    # the mission so every aligner writes that one chunk: two alignments then
    # conflict on its rows, where chunks made by each would split it in two.
    parts, tables = [_Part(FRAMES, 0, list)], GRAPH_TABLES
    if source.landmarks:
        # the table only when needed: a repository may use the name for its own table
        tables = {**GRAPH_TABLES, LANDMARKS: Landmark}
        parts.append(_Part(LANDMARKS, len(source.landmarks), partial(landmark_rows, source)))
        summary += f", {len(source.landmarks)} landmarks"
    for tile in tiles:
        vertices = partial(vertex_rows, source, tile.vertices)
        parts.append(_Part(VERTICES, len(tile.vertices), vertices, tile))
        if tile.edges:
            edges = partial(edge_rows, source, tile.edges)
            parts.append(_Part(EDGES, len(tile.edges), edges, tile))
    if isinstance(source, LaserMission) and source.scans:
        # a scan is a block of its own, all in one chunk as a cloud's blocks are
        parts.append(_Part(CLOUDS, len(source.scans), partial(scan_blocks, source)))
        tables = {**tables, **LASER_TABLES}
        summary += f", {len(source.scans)} scans of {source.point_count()} points"
    return _Prepared(source, mission_to_pb(source), parts, tables, summary)


async def _import(peer: Peer, prepared: _Prepared, progress: Progress | None) -> ImportResult:
    source = prepared.source
    written = await _commit_rows(peer, prepared, progress)
    log.info("imported mission %s (%s)", source.name, prepared.summary)
    if isinstance(source, PointCloud | OccupancyGrid):
        vertices, edges, landmarks = 0, 0, 0
        points = len(source.points) if isinstance(source, PointCloud) else 0
    else:
        vertices, edges = len(source.vertices), len(source.edges)
        points = source.point_count() if isinstance(source, LaserMission) else 0
        landmarks = len(source.landmarks)
    return ImportResult(
        source.name,
        source.robot,
        vertices,
        edges,
        source.bbox(),
        written.chunks,
        written.commit,
        points,
        written.seconds,
        written.tiles,
        landmarks,
        tuple(source.warnings) if isinstance(source, PointCloud) else (),
        source.correction if isinstance(source, LaserMission) else None,
    )


async def import_graph(
    peer: Peer,
    graph: MissionGraph,
    mission: str | None = None,
    robot: str | None = None,
    progress: Progress | None = None,
) -> ImportResult:
    """Write a mission (its row, vertices and edges) in one commit.

    Args:
        peer: where to write; the tables are created when missing.
        graph: the parsed mission.
        mission: store it under this name instead of `graph.name`.
        robot: store it with this robot instead of `graph.robot`.
        progress: called with (rows staged, rows in all) while staging.

    Returns:
        What was written, with the new chunks and the commit.

    Raises:
        MapImportError: the graph is not importable, or the mission exists already.
        ConflictError: someone committed a mission of the same name meanwhile.
    """
    prepared = await peer.off_loop(_prepare, rename(graph, mission, robot))
    return await _import(peer, prepared, progress)


async def import_cloud(
    peer: Peer, cloud: PointCloud, progress: Progress | None = None
) -> ImportResult:
    """Write a point cloud (its mission row and point blocks) in one commit.

    Raises:
        MapImportError: no points, or the mission exists already.
        ConflictError: someone committed a mission of the same name meanwhile.
    """
    return await _import(peer, await peer.off_loop(_prepare, cloud), progress)


async def import_missions(
    peer: Peer, sources: Sequence[MapSource], progress: Progress | None = None
) -> list[ImportResult]:
    """Import graphs and clouds, one commit per mission. Every mission is built
    and checked, and no name may repeat or exist already, before the first
    commit, so a bad mission writes nothing of the set.

    Raises:
        MapImportError: a name repeats or exists already, or a mission is not importable.
    """
    names = [s.name for s in sources]
    clashes = sorted({n for n in names if names.count(n) > 1} | (set(names) & await _held(peer)))
    if clashes:
        raise MapImportError(
            f"mission {', '.join(map(repr, clashes))} exists already; pass another name"
        )
    # building and encoding 100,000 rows takes seconds: not on the event loop (issue 14 §1)
    prepared = await peer.off_loop(_prepare_all, sources)
    return [await _import(peer, p, progress) for p in prepared]


def _prepare_all(sources: Sequence[MapSource]) -> list[_Prepared]:
    return [_prepare(source) for source in sources]


async def import_graphs(
    peer: Peer, graphs: Sequence[MissionGraph], progress: Progress | None = None
) -> list[ImportResult]:
    """`import_graph` each mission in turn: one commit per mission."""
    return await import_missions(peer, graphs, progress)


async def _held(peer: Peer) -> set[str]:
    if MISSIONS not in peer.tables():
        return set()
    async with reading(peer) as tx:
        return await mission_names(tx)


@dataclass(frozen=True)
class _Written:
    chunks: dict[str, ChunkId]
    tiles: tuple[TileChunks, ...]
    commit: CommitId
    seconds: float  # what the commit itself took


async def _commit_rows(peer: Peer, prepared: _Prepared, progress: Progress | None) -> _Written:
    """Stage one mission's rows in new chunks (one per part) and commit them; on
    any failure, forget the staged rows and the chunks."""
    name = prepared.source.name
    await ensure_tables(peer, prepared.tables)
    tx = peer.begin()
    if name in await mission_names(tx):
        tx.abort()
        raise MapImportError(f"mission {name!r} exists already; pass another name")
    created: list[ChunkId] = []
    try:
        created.append(await peer.create_chunk(MISSIONS))
        for part in prepared.parts:
            created.append(await peer.create_chunk(part.table))
        chunks, tiles = _name_chunks(prepared, created)
        await peer.off_loop(_stage, tx, prepared, created, progress)  # encodes every row
        started = time.perf_counter()
        record = await tx.commit(f"import mission {name}: {prepared.summary}")
    except BaseException:
        await _undo(peer, tx, created)
        raise
    assert record is not None  # a mission row is always written
    return _Written(chunks, tiles, record.id, time.perf_counter() - started)


def _name_chunks(
    prepared: _Prepared, created: Sequence[ChunkId]
) -> tuple[dict[str, ChunkId], tuple[TileChunks, ...]]:
    """Write the chunks into the mission row (a peer that finds the mission by
    its box then learns where its tiles' edges are, which the spatial index
    cannot place), and return them: table -> chunk for the untiled parts, and
    the tiles."""
    mission = prepared.mission
    chunks = {MISSIONS: created[0]}
    tiles: dict[int, TileChunks] = {}
    for part, chunk in zip(prepared.parts, created[1:], strict=True):
        if part.tile is None:
            chunks[part.table] = chunk
        elif part.table == VERTICES:
            tile = part.tile
            tiles[id(tile)] = TileChunks(
                chunk, None, tile.bbox, len(tile.vertices), len(tile.edges)
            )
        else:
            tiles[id(part.tile)] = replace(tiles[id(part.tile)], edges=chunk)
    mission.chunks.update(chunks)
    mission.tiles.extend(t.to_pb() for t in tiles.values())
    return chunks, tuple(tiles.values())


def _stage(
    tx: Transaction, prepared: _Prepared, created: Sequence[ChunkId], progress: Progress | None
) -> None:
    parts = [_Part(MISSIONS, 1, lambda: [prepared.mission]), *prepared.parts]
    total = sum(p.count for p in parts)
    done = 0
    for part, chunk in zip(parts, created, strict=True):
        rows = part.rows()  # encoded below, then let go
        for start in range(0, len(rows), _PROGRESS_EVERY):
            batch = rows[start : start + _PROGRESS_EVERY]
            tx.insert_many(part.table, batch, chunk)
            done += len(batch)
            if progress is not None:
                progress(done, total)


async def _undo(peer: Peer, tx: Transaction, chunks: Sequence[ChunkId]) -> None:
    """Forget a failed import's staged rows and its (empty) chunks."""
    try:
        tx.abort()
    except Exception:  # already closed by a failed commit; nothing is buffered then
        log.debug("transaction could not be aborted", exc_info=True)
    for chunk in chunks:
        await peer.leave_chunk(chunk, force=True)
