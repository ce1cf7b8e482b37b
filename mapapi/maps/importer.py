"""Store pose graphs in a peer: one transaction per mission, all or nothing.

Each mission gets one chunk per table (missions, vertices, edges) by default.
Everything is built and checked first; chunks are created and rows staged only
then, and committed once, so a failing import leaves no rows and no chunks.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

from mapapi.ids import ChunkId, CommitId
from mapapi.maps.errors import MapImportError
from mapapi.maps.graph import GraphEdge, MissionGraph
from mapapi.maps.schema import (
    EDGES,
    GRAPH_TABLES,
    MISSIONS,
    VERTICES,
    edge_from_pb,
    edge_to_pb,
    mission_to_pb,
    pose_from_pb,
    vertex_to_pb,
)
from mapapi.spatial import BBox

if TYPE_CHECKING:
    from google.protobuf.message import Message

    from mapapi.peer import Peer
    from mapapi.transaction import Transaction

log = logging.getLogger(__name__)

Progress = Callable[[int, int], None]  # (rows staged, rows in all)
_PROGRESS_EVERY = 10_000


@dataclass(frozen=True)
class ImportResult:
    """What one mission's import wrote."""

    mission: str
    robot: str
    vertices: int
    edges: int
    bbox: BBox | None
    chunks: dict[str, ChunkId]
    commit: CommitId


async def ensure_tables(peer: Peer) -> None:
    """Create the graph tables that do not exist yet.

    Raises:
        MapImportError: a table of that name holds another type.
    """
    existing = peer.tables()
    for name, cls in GRAPH_TABLES.items():
        wanted = cls.DESCRIPTOR.full_name
        if name in existing and existing[name].type_name != wanted:
            raise MapImportError(
                f"table {name!r} holds {existing[name].type_name}, not {wanted}; "
                "import into another repository"
            )
    for name, cls in GRAPH_TABLES.items():
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


def build_rows(graph: MissionGraph) -> dict[str, list[Message]]:
    """Every row of a mission, by table, checked.

    Raises:
        MapImportError: no vertices, or an edge names a vertex the mission lacks.
    """
    if not graph.name:
        raise MapImportError("a mission needs a name")
    if not graph.vertices:
        raise MapImportError("the graph has no vertices", source=graph.name)
    name = graph.name
    for edge in graph.edges:
        for end in (edge.source, edge.target):
            if end[0] == name and end[1] not in graph.vertices:
                raise MapImportError(f"an edge names the missing vertex {end[1]}", source=name)
    return {
        MISSIONS: [mission_to_pb(graph)],
        VERTICES: [vertex_to_pb(name, i, pose) for i, pose in graph.vertices.items()],
        EDGES: [edge_to_pb(name, edge) for edge in graph.edges],
    }


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
    graph = rename(graph, mission, robot)
    rows = build_rows(graph)
    await ensure_tables(peer)
    tx = peer.begin()
    existing = await tx.items(MISSIONS)
    if any(getattr(m, "name", None) == graph.name for m in existing.values()):
        tx.abort()
        raise MapImportError(f"mission {graph.name!r} exists already; pass another name")
    chunks: dict[str, ChunkId] = {}
    try:
        for table in rows:
            chunks[table] = await peer.create_chunk(table)
        _stage(tx, rows, chunks, progress)
        record = await tx.commit(
            f"import mission {graph.name}: {len(graph.vertices)} vertices, {len(graph.edges)} edges"
        )
    except BaseException:
        await _undo(peer, tx, chunks)
        raise
    assert record is not None  # a mission row is always written
    log.info("imported mission %s (%d elements)", graph.name, graph.elements())
    return ImportResult(
        graph.name,
        graph.robot,
        len(graph.vertices),
        len(graph.edges),
        graph.bbox(),
        chunks,
        record.id,
    )


def _stage(
    tx: Transaction,
    rows: dict[str, list[Message]],
    chunks: dict[str, ChunkId],
    progress: Progress | None,
) -> None:
    total = sum(len(r) for r in rows.values())
    done = 0
    for table, messages in rows.items():
        chunk = chunks[table]
        for message in messages:
            tx.insert(table, message, chunk)
            done += 1
            if progress is not None and done % _PROGRESS_EVERY == 0:
                progress(done, total)
    if progress is not None:
        progress(done, total)


async def _undo(peer: Peer, tx: Transaction, chunks: dict[str, ChunkId]) -> None:
    """Forget a failed import's staged rows and its (empty) chunks."""
    try:
        tx.abort()
    except Exception:  # already closed by a failed commit; nothing is buffered then
        log.debug("transaction could not be aborted", exc_info=True)
    for chunk in chunks.values():
        await peer.leave_chunk(chunk, force=True)


async def import_graphs(
    peer: Peer, graphs: Iterable[MissionGraph], progress: Progress | None = None
) -> list[ImportResult]:
    """`import_graph` each mission in turn: one commit per mission."""
    return [await import_graph(peer, g, progress=progress) for g in graphs]


async def load_graph(peer: Peer, mission: str) -> MissionGraph:
    """Read a stored mission back as a `MissionGraph` (vertices by index).

    Raises:
        MapImportError: no such mission.
    """
    tx = peer.begin()
    found = [m for m in (await tx.items(MISSIONS)).values() if getattr(m, "name", "") == mission]
    if not found:
        raise MapImportError(f"no mission {mission!r}")
    row = found[0]
    vertices = {
        v.index: pose_from_pb(v.pose)
        for v in (await tx.items(VERTICES)).values()
        if getattr(v, "mission", "") == mission
    }
    edges = [
        edge_from_pb(e)  # type: ignore[arg-type]
        for e in (await tx.items(EDGES)).values()
        if getattr(e, "mission", "") == mission
    ]
    tx.abort()
    return MissionGraph(
        mission,
        getattr(row, "robot", ""),
        getattr(row, "frame", ""),
        dict(sorted(vertices.items())),
        edges,
    )
