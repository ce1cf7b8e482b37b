"""Read stored missions back: their names, a summary of each, a graph or a cloud.

Everything here reads through one transaction, so a listing or a mission is
consistent as of one logical time even while others commit.
"""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator, Iterable
from contextlib import asynccontextmanager
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

from mapapi.core.ids import ChunkId, PeerId
from mapapi.lookup.spatial import BBox
from mapapi.maps.cloud import PointCloud, cloud_from_blocks
from mapapi.maps.errors import MapImportError
from mapapi.maps.graph import MissionGraph, Origin
from mapapi.maps.schema import (
    CLOUDS,
    EDGES,
    MISSIONS,
    VERTICES,
    box_from_pb,
    edge_from_pb,
    pose_from_pb,
)

if TYPE_CHECKING:
    from mapapi.core.transaction import Transaction
    from mapapi.service.peer import Peer

log = logging.getLogger(__name__)


@dataclass
class MissionInfo:
    """A summary of one mission held here.

    Attributes:
        chunks: table -> the chunk of that table holding the mission's rows.
        holders: the peers holding the mission row's chunk.
    """

    name: str
    robot: str
    frame: str
    bbox: BBox | None
    vertices: int = 0
    edges: int = 0
    points: int = 0
    chunks: dict[str, ChunkId] = field(default_factory=dict)
    holders: list[PeerId] = field(default_factory=list)

    @property
    def kind(self) -> str:
        """What the mission holds: "cloud" when it has points, else "graph"."""
        return "cloud" if self.points else "graph"


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


async def _rows_of(peer: Peer, tx: Transaction, table: str, mission: str) -> list[Any]:
    if table not in peer.tables():
        return []
    return [m for m in (await tx.items(table)).values() if getattr(m, "mission", "") == mission]


async def _mission_row(peer: Peer, tx: Transaction, mission: str) -> Any:
    rows = (await tx.items(MISSIONS)).values() if MISSIONS in peer.tables() else []
    found = [m for m in rows if getattr(m, "name", "") == mission]
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

    Raises:
        MapImportError: no such mission.
    """
    async with reading(peer) as tx:
        row = await _mission_row(peer, tx, mission)
        vertices = await _in_order(peer, tx, VERTICES, mission)
        edges = await _in_order(peer, tx, EDGES, mission)
    graph = MissionGraph(mission, row.robot, row.frame)
    records = [(key, 0, v) for key, v in vertices] + [(key, 1, e) for key, e in edges]
    records.sort(key=lambda record: (record[0][0], record[0][1], record[1], record[0][2:]))
    # lines renumbered in that order, so the writer interleaves vertices and edges as read
    for line, (_, kind, message) in enumerate(records, 1):
        if kind == 0:
            graph.vertices[message.index] = pose_from_pb(message.pose)
            graph.origins[message.index] = Origin(line, message.origin.text)
        else:
            edge = edge_from_pb(message)
            graph.edges.append(replace(edge, origin=Origin(line, edge.origin.text)))
    return graph


async def _in_order(
    peer: Peer, tx: Transaction, table: str, mission: str
) -> list[tuple[tuple[int, int, int, str], Any]]:
    """The mission's rows of `table` with their sort keys: (insertion time,
    line, index (vertices), id)."""
    if table not in peer.tables():
        return []
    decode = peer.table(table).decode
    rows = []
    for revision in await peer.scan(tx.begin_time, table, None):
        message: Any = decode(revision.data)
        if message.mission == mission:
            index = message.index if table == VERTICES else 0
            key = (revision.insert_time, message.origin.line, index, str(revision.item_id))
            rows.append((key, message))
    return rows


async def load_cloud(peer: Peer, mission: str) -> PointCloud:
    """Read a stored mission's point cloud back (its points in block order).

    Raises:
        MapImportError: no such mission.
    """
    async with reading(peer) as tx:
        row = await _mission_row(peer, tx, mission)
        blocks = await _rows_of(peer, tx, CLOUDS, mission)
    return cloud_from_blocks(mission, row.robot, row.frame, blocks)


async def mission_chunks(peer: Peer, names: Iterable[str]) -> dict[str, dict[str, ChunkId]]:
    """Mission name -> {table: chunk} for the missions of `names` held here, as
    their rows name them (rows written before rows named their chunks name none)."""
    wanted = set(names)
    if not wanted or MISSIONS not in peer.tables():
        return {}
    async with reading(peer) as tx:
        rows = [m for m in (await tx.items(MISSIONS)).values() if m.name in wanted]
    found: dict[str, dict[str, ChunkId]] = {}
    for row in rows:
        found[row.name] = {}
        for table, chunk in row.chunks.items():
            try:
                found[row.name][table] = ChunkId(chunk)
            except ValueError:  # a row written by hand, not by an import
                log.warning("mission %s names no chunk id for %s: %r", row.name, table, chunk)
    return found


async def list_missions(peer: Peer) -> list[MissionInfo]:
    """Every mission held here, by name, with its counts, chunks and holders."""
    async with reading(peer) as tx:
        infos = await _summaries(peer, tx)
    for info in infos.values():
        chunk = info.chunks.get(MISSIONS)
        info.holders = peer.holders(chunk) if chunk is not None else []
    return [infos[name] for name in sorted(infos)]


async def _summaries(peer: Peer, tx: Transaction) -> dict[str, MissionInfo]:
    infos: dict[str, MissionInfo] = {}
    for chunk, row in await _by_chunk(peer, tx, MISSIONS):
        box = box_from_pb(row.bbox) if row.HasField("bbox") else None
        infos[row.name] = MissionInfo(row.name, row.robot, row.frame, box)
        infos[row.name].chunks[MISSIONS] = chunk
    for table in (VERTICES, EDGES, CLOUDS):
        for chunk, row in await _by_chunk(peer, tx, table):
            info = infos.get(row.mission)
            if info is None:
                continue  # rows whose mission row is not held here
            info.chunks.setdefault(table, chunk)
            if table == VERTICES:
                info.vertices += 1
            elif table == EDGES:
                info.edges += 1
            else:
                info.points += row.count
    return infos


async def _by_chunk(peer: Peer, tx: Transaction, table: str) -> list[tuple[ChunkId, Any]]:
    """Every (chunk, row) of `table` held here."""
    if table not in peer.tables():
        return []
    rows: list[tuple[ChunkId, Any]] = []
    for info in peer.chunks(table):
        rows += [(info.id, m) for m in (await tx.items(table, info.id)).values()]
    return rows
