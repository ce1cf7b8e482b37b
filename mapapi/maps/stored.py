"""Read stored missions back: their names, a summary of each, a graph or a cloud.

A mission's rows are read by its label (`mapapi.maps.labels`): through the
store's label index, only that mission's rows are read, however many missions
the store holds. Reads of rows go through one transaction, so a mission is
consistent as of one logical time even while others commit; the listing's
counts and boxes are the summaries the store keeps up to date at every commit.

Reading a mission of 100,000 rows takes seconds of decoding: the async readers
do it in a worker thread (`Peer.off_loop`), and the sync ones (`graph_at`,
`cloud_at`, at a time `read_time` gives) in whatever thread or process calls
them (`mapapi.maps.jobs`), so a serving peer's event loop keeps answering.
"""

from __future__ import annotations

import fnmatch
import logging
from collections.abc import AsyncIterator, Collection, Iterable, Sequence
from contextlib import asynccontextmanager
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

from mapapi.core.errors import UsageError
from mapapi.core.ids import ChunkId, PeerId
from mapapi.lookup.spatial import BBox
from mapapi.maps.cloud import PointCloud, cloud_from_blocks
from mapapi.maps.errors import MapImportError
from mapapi.maps.graph import MissionGraph
from mapapi.maps.labels import MAP_LABELS
from mapapi.maps.schema import (
    CLOUDS,
    EDGES,
    FRAMES,
    GRIDS,
    LANDMARKS,
    MISSIONS,
    VERTICES,
    Landmark,
    box_from_pb,
    edge_from_pb,
    landmark_from_pb,
    origin_from_pb,
    pose_from_pb,
)
from mapapi.maps.tiles import TileChunks

if TYPE_CHECKING:
    from mapapi.core.history import Revision
    from mapapi.core.transaction import Transaction
    from mapapi.service.peer import Peer

log = logging.getLogger(__name__)


@dataclass
class MissionInfo:
    """A summary of one mission held here.

    Attributes:
        chunks: table -> the chunk of that table holding the mission's rows, for
            the tables not tiled (all of them for a mission imported before tiles).
        tiles: its graph's spatial tiles, as its row lists them.
        holders: the peers holding the mission row's chunk.
        landmarks: how many of its landmarks are held here.
    """

    name: str
    robot: str
    frame: str
    bbox: BBox | None
    vertices: int = 0
    edges: int = 0
    points: int = 0
    chunks: dict[str, ChunkId] = field(default_factory=dict)
    tiles: tuple[TileChunks, ...] = ()
    holders: list[PeerId] = field(default_factory=list)
    landmarks: int = 0

    @property
    def kind(self) -> str:
        """What the mission holds: "grid" for an occupancy grid's tiles, "cloud"
        when it has points and no poses, else "graph" (a laser mission has both:
        its trajectory is its graph)."""
        if GRIDS in self.chunks:
            return "grid"
        return "cloud" if self.points and not self.vertices else "graph"


@asynccontextmanager
async def reading(peer: Peer) -> AsyncIterator[Transaction]:
    """A transaction begun now, to read in; aborted afterwards (it never writes)."""
    tx = peer.begin()
    try:
        yield tx
    finally:
        tx.abort()


async def mission_names(tx: Transaction) -> set[str]:
    """The names of the missions `tx` sees (the missions table must exist)."""
    return {str(getattr(m, "name", "")) for m in (await tx.items(MISSIONS)).values()}


def rows_of(peer: Peer, time: int, table: str, mission: str) -> list[Any]:
    """The mission's rows of `table` visible at `time`, decoded, by id."""
    if table not in peer.store.tables():
        return []
    decode = peer.table(table).decode
    return [decode(r.data) for r in peer.scan_labelled_now(time, MAP_LABELS, mission, table)]


GRAPH_READ = (MISSIONS, VERTICES, LANDMARKS, EDGES)
"""The tables `graph_at` reads."""

CLOUD_READ = (MISSIONS, CLOUDS)
"""The tables `cloud_at` reads."""


@asynccontextmanager
async def read_time(
    peer: Peer, missions: Iterable[str], tables: Sequence[str]
) -> AsyncIterator[int]:
    """A time to read `missions` at (their rows of `tables`), at which their
    chunks read as every replica will from now on, so no commit at or before it
    can still arrive there (`Peer.labelled_readable`): the sync readers below
    (`graph_at`, `cloud_at`) read at it from any thread or process. A read-only
    transaction stays open until the block ends."""
    async with reading(peer) as tx:
        yield await peer.labelled_readable(MAP_LABELS, list(missions), tables, tx.begin_time)


def mission_row(peer: Peer, time: int, mission: str) -> Any:
    """The mission's row visible at `time`.

    Raises:
        MapImportError: no such mission here.
    """
    found = rows_of(peer, time, MISSIONS, mission)
    if not found:
        raise MapImportError(
            f"no mission {mission!r} here; `mapctl missions` lists them, "
            "`mapctl query-bbox --load` fetches others' missions"
        )
    return found[0]


async def load_graph(peer: Peer, mission: str) -> MissionGraph:
    """Read a stored mission back as a `MissionGraph`, its vertices and edges in
    insertion order: by insertion time, then their line in the imported file
    (vertices without one first, by index), then id. Every peer holding the
    mission thus reads the same graph in the same order (`write_g2o` keeps it).
    The rows are read and decoded in a worker thread (`Peer.off_loop`).

    Raises:
        MapImportError: no such mission.
    """
    async with read_time(peer, [mission], GRAPH_READ) as time:
        return await peer.off_loop(graph_at, peer, time, mission)


def graph_at(peer: Peer, time: int, mission: str) -> MissionGraph:
    """`load_graph` at `time` (from `read_time`), in any thread (it only reads the store).

    Raises:
        MapImportError: no such mission.
    """
    row = mission_row(peer, time, mission)
    graph = MissionGraph(mission, row.robot, row.frame)
    records = [(key, 0, v) for key, v in _in_order(peer, time, VERTICES, mission)]
    records += [(key, 0, m) for key, m in _in_order(peer, time, LANDMARKS, mission)]
    records += [(key, 1, e) for key, e in _in_order(peer, time, EDGES, mission)]
    records.sort(key=lambda record: (record[0][0], record[0][1], record[1], record[0][2:]))
    # lines renumbered in that order, so the writer interleaves records as read
    for line, (_, kind, message) in enumerate(records, 1):
        origin = replace(origin_from_pb(message.origin), line=line)
        if isinstance(message, Landmark):
            graph.landmarks[message.index] = landmark_from_pb(message)
            graph.landmark_origins[message.index] = origin
        elif kind == 0:
            graph.vertices[message.index] = pose_from_pb(message.pose)
            graph.origins[message.index] = origin
            if message.timestamp:
                graph.timestamps[message.index] = message.timestamp
        else:
            edge = edge_from_pb(message)
            graph.edges.append(replace(edge, origin=replace(edge.origin, line=line)))
    return graph


def _in_order(
    peer: Peer, time: int, table: str, mission: str
) -> list[tuple[tuple[int, int, int, str], Any]]:
    """The mission's rows of `table` with their sort keys: (insertion time,
    line, index (vertices, landmarks), id)."""
    if table not in peer.store.tables():
        return []
    decode = peer.table(table).decode
    rows = []
    for revision in peer.scan_labelled_now(time, MAP_LABELS, mission, table):
        message: Any = decode(revision.data)
        index = message.index if table in (VERTICES, LANDMARKS) else 0
        key = (revision.insert_time, message.origin.line, index, str(revision.item_id))
        rows.append((key, message))
    return rows


async def load_cloud(peer: Peer, mission: str) -> PointCloud:
    """Read a stored mission's point cloud back (its points in block order), in a
    worker thread.

    Raises:
        MapImportError: no such mission.
    """
    async with read_time(peer, [mission], CLOUD_READ) as time:
        return await peer.off_loop(cloud_at, peer, time, mission)


def cloud_at(peer: Peer, time: int, mission: str) -> PointCloud:
    """`load_cloud` at `time` (from `read_time`), in any thread.

    Raises:
        MapImportError: no such mission.
    """
    row = mission_row(peer, time, mission)
    blocks = rows_of(peer, time, CLOUDS, mission)
    return cloud_from_blocks(mission, row.robot, row.frame, blocks)


@dataclass(frozen=True)
class MissionParts:
    """Where a mission's rows are, as its mission row names them.

    Attributes:
        chunks: table -> chunk, for the tables of one chunk per mission (the
            mission row's, a cloud's; a graph's vertices and edges too when it
            was imported before tiles).
        tiles: the graph's spatial tiles (`mapapi.maps.tiles`).
    """

    chunks: dict[str, ChunkId]
    tiles: tuple[TileChunks, ...] = ()

    def in_box(self, box: BBox, found: Collection[ChunkId] = ()) -> set[ChunkId]:
        """The chunks a load of `box` needs: the untiled ones, and the chunks of
        every tile whose box overlaps `box` or whose vertices are among `found`
        (the spatial index places a tile where its vertices are now: one moved
        out of the box the row lists is found there, and its edges must come)."""
        tiled = {
            c for t in self.tiles if t.bbox.overlaps(box) or t.vertices in found for c in t.chunks()
        }
        return set(self.chunks.values()) | tiled


async def mission_parts(peer: Peer, names: Iterable[str]) -> dict[str, MissionParts]:
    """Mission name -> where its rows are, for the missions of `names` held here,
    as their rows name them (rows written before rows named their chunks name
    none; a row written by hand with ids that are not ids names none either)."""
    wanted = set(names)
    if not wanted or MISSIONS not in peer.store.tables():
        return {}
    async with read_time(peer, sorted(wanted), (MISSIONS,)) as time:
        rows = await peer.off_loop(_mission_rows, peer, time, sorted(wanted))
    return {row.name: _parts_of(row) for row in rows}


def _parts_of(row: Any) -> MissionParts:
    chunks: dict[str, ChunkId] = {}
    for table, chunk in row.chunks.items():
        try:
            chunks[table] = ChunkId(chunk)
        except ValueError:
            log.warning("mission %s names no chunk id for %s: %r", row.name, table, chunk)
    tiles = []
    for tile in row.tiles:
        try:
            tiles.append(TileChunks.from_pb(tile))
        except ValueError as exc:
            log.warning("mission %s names a tile that is not one: %s", row.name, exc)
    return MissionParts(chunks, tuple(tiles))


def _mission_rows(peer: Peer, time: int, names: list[str]) -> list[Any]:
    return [row for name in names for row in rows_of(peer, time, MISSIONS, name)]


async def list_missions(peer: Peer) -> list[MissionInfo]:
    """Every mission held here, by name, with its counts, box, chunks and holders.

    Reads one row per mission (its mission row) and the summaries the store
    keeps per mission and chunk (`Peer.label_summaries`): counts are of the
    rows held here, and the box is the one around the vertices, landmarks and
    point blocks held here (the mission row's box when none is held)."""
    if MISSIONS not in peer.store.tables():
        return []
    rows = await peer.scan_newest(MISSIONS)  # each mission as of its newest commit
    return await peer.off_loop(_missions_of, peer, rows)


def _missions_of(peer: Peer, rows: list[Revision]) -> list[MissionInfo]:
    """The missions of their rows, with the store's summaries (in a worker thread)."""
    decode = peer.table(MISSIONS).decode
    infos: dict[str, MissionInfo] = {}
    for revision in rows:
        row: Any = decode(revision.data)
        box = box_from_pb(row.bbox) if row.HasField("bbox") else None
        parts = _parts_of(row)  # the chunks its row names: a frames chunk has no rows yet
        infos[row.name] = MissionInfo(
            row.name, row.robot, row.frame, box, chunks=dict(parts.chunks), tiles=parts.tiles
        )
        infos[row.name].chunks[MISSIONS] = revision.chunk_id
    boxes: dict[str, list[BBox]] = {}
    for summary in peer.label_summaries(MAP_LABELS):
        info = infos.get(summary.label)
        if info is None or summary.table in (MISSIONS, FRAMES):
            continue  # rows whose mission row is not held here; places lie in the world frame
        if not (info.tiles and summary.table in (VERTICES, EDGES)):
            info.chunks.setdefault(summary.table, summary.chunk)
        if summary.table == VERTICES:
            info.vertices += summary.items
        elif summary.table == EDGES:
            info.edges += summary.items
        elif summary.table == LANDMARKS:
            info.landmarks += summary.items
        elif summary.table == CLOUDS:
            info.points += summary.weight
        if summary.box is not None:
            boxes.setdefault(summary.label, []).append(BBox.from_tuple(summary.box))
    for name, found in boxes.items():
        infos[name].bbox = BBox.enclosing(found)
    for info in infos.values():
        info.holders = peer.holders(info.chunks[MISSIONS])
    return [infos[name] for name in sorted(infos)]


def choose_missions(
    held: list[MissionInfo], names: list[str] | None, box: BBox | None
) -> list[MissionInfo]:
    """The missions named (default: those in `box`, or all) held here, to draw or
    align (see `plot_map`); a name may be a shell pattern
    (`tunnels-*`).

    Raises:
        UsageError: a name or pattern matches no mission held here, or none is left to draw.
    """
    if names:
        missing = [n for n in names if not any(fnmatch.fnmatchcase(i.name, n) for i in held)]
        if missing:
            raise UsageError(
                f"no mission {', '.join(map(repr, missing))} here; `mapctl missions` lists them"
            )
        return [i for i in held if any(fnmatch.fnmatchcase(i.name, n) for n in names)]
    chosen = [i for i in held if box is None or (i.bbox is not None and i.bbox.overlaps(box))]
    if not chosen:
        where = " in that box" if box is not None else ""
        raise UsageError(f"no mission held here{where}; import one with `mapctl import`")
    return chosen
