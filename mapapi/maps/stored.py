"""Read stored missions back: their names, a summary of each, a graph or a cloud.

A mission's rows are read by its label (`mapapi.maps.labels`): through the
store's label index, only that mission's rows are read, however many missions
the store holds. Reads of rows go through one transaction, so a mission is
consistent as of one logical time even while others commit; the listing's
counts and boxes are the summaries the store keeps up to date at every commit.
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
from mapapi.maps.labels import MAP_LABELS
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
    """The mission's rows of `table` that `tx` sees, decoded, by id."""
    if table not in peer.store.tables():
        return []
    decode = peer.table(table).decode
    return [
        decode(r.data) for r in await peer.scan_labelled(tx.begin_time, MAP_LABELS, mission, table)
    ]


async def _mission_row(peer: Peer, tx: Transaction, mission: str) -> Any:
    found = await _rows_of(peer, tx, MISSIONS, mission)
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
    if table not in peer.store.tables():
        return []
    decode = peer.table(table).decode
    rows = []
    for revision in await peer.scan_labelled(tx.begin_time, MAP_LABELS, mission, table):
        message: Any = decode(revision.data)
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
    if not wanted or MISSIONS not in peer.store.tables():
        return {}
    async with reading(peer) as tx:
        rows = [row for name in sorted(wanted) for row in await _rows_of(peer, tx, MISSIONS, name)]
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
    """Every mission held here, by name, with its counts, box, chunks and holders.

    Reads one row per mission (its mission row) and the summaries the store
    keeps per mission and chunk (`Peer.label_summaries`): counts are of the
    rows held here, and the box is the one around the vertices, landmarks and
    point blocks held here (the mission row's box when none is held)."""
    if MISSIONS not in peer.store.tables():
        return []
    async with reading(peer) as tx:
        rows = await peer.scan(tx.begin_time, MISSIONS, None)
    decode = peer.table(MISSIONS).decode
    infos: dict[str, MissionInfo] = {}
    for revision in rows:
        row: Any = decode(revision.data)
        box = box_from_pb(row.bbox) if row.HasField("bbox") else None
        infos[row.name] = MissionInfo(row.name, row.robot, row.frame, box)
        infos[row.name].chunks[MISSIONS] = revision.chunk_id
    boxes: dict[str, list[BBox]] = {}
    for summary in peer.label_summaries(MAP_LABELS):
        info = infos.get(summary.label)
        if info is None or summary.table == MISSIONS:
            continue  # rows whose mission row is not held here
        info.chunks.setdefault(summary.table, summary.chunk)
        if summary.table == VERTICES:
            info.vertices += summary.items
        elif summary.table == EDGES:
            info.edges += summary.items
        elif summary.table == CLOUDS:
            info.points += summary.weight
        if summary.box is not None:
            boxes.setdefault(summary.label, []).append(BBox.from_tuple(summary.box))
    for name, found in boxes.items():
        infos[name].bbox = BBox.enclosing(found)
    for info in infos.values():
        info.holders = peer.holders(info.chunks[MISSIONS])
    return [infos[name] for name in sorted(infos)]
