"""Cost follows the mission (issue 14 §2): the store indexes every mission's rows
and keeps a summary per mission, so `missions` reads one row per mission and
export and plot read only the mission's rows, and the summary stays right after
edits, removals and conflicts resolved (replication and participation: in
tests/swarm/test_maps_summary_swarm.py)."""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

import pytest

from mapapi import ConflictError, ItemId, Peer
from mapapi.lookup.spatial import BBox
from mapapi.maps import EDGES, MISSIONS, VERTICES, import_graph, list_missions, read_g2o
from mapapi.maps.labels import MAP_LABELS
from mapapi.maps.operations import MapOperations
from mapapi.maps.schema import FRAMES, Vertex, pose_to_pb
from mapapi.maps.se3 import IDENTITY
from mapapi.store.labels import summarise

SAMPLES = Path(__file__).resolve().parents[2] / "sample_maps"
INTEL = SAMPLES / "pose_graphs" / "intel.g2o"  # 1,728 vertices, 2,512 edges

MakePeer = Callable[..., Awaitable[Peer]]


@pytest.fixture
async def two(make_peer: MakePeer) -> Peer:
    """A peer on a real repository holding the Intel graph twice: "intel" and "other"."""
    peer = await make_peer()
    graph = read_g2o(INTEL)
    await import_graph(peer, graph)
    await import_graph(peer, graph, mission="other")
    return peer


def from_scratch(peer: Peer) -> list[Any]:
    """The summaries counted anew from every row held now (the oracle)."""
    store = peer.store
    return summarise(store.scan(store.clock()), MAP_LABELS, store.tables())


async def listing(peer: Peer) -> dict[str, tuple[int, int, BBox | None]]:
    return {i.name: (i.vertices, i.edges, i.bbox) for i in await list_missions(peer)}


async def ids(peer: Peer, table: str, field: str, value: Any, mission: str) -> list[ItemId]:
    tx = peer.begin()
    found = await tx.find(table, field, value)
    tx.abort()
    return [i for i, m in found.items() if m.mission == mission]


@pytest.fixture
def table_scans(two: Peer, monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """The tables the store reads whole from now on (a chunk's scan is not one)."""
    scans: list[str] = []
    scan = two.store.scan

    def counting(time: int, *, table: str | None = None, chunk: Any = None) -> Any:
        if chunk is None:
            scans.append(str(table))
        return scan(time, table=table, chunk=chunk)

    monkeypatch.setattr(two.store, "scan", counting)
    return scans


async def test_the_listing_reads_one_row_per_mission_and_the_summaries(
    two: Peer, table_scans: list[str]
) -> None:
    infos = await list_missions(two)

    assert table_scans == [MISSIONS]  # never the vertices or the edges
    assert [(i.name, i.vertices, i.edges) for i in infos] == [
        ("intel", 1_728, 2_512),
        ("other", 1_728, 2_512),
    ]
    intel, other = infos
    assert intel.bbox == other.bbox
    assert intel.bbox is not None
    assert (intel.bbox.xmin, intel.bbox.ymin) < (-9.4, -22.4)
    assert set(intel.chunks) == {MISSIONS, FRAMES}  # its vertices and edges are in tiles
    assert [t.vertex_count for t in intel.tiles] == [432] * 4
    chunks_of = [{*i.chunks.values(), *(c for t in i.tiles for c in t.chunks())} for i in infos]
    assert not chunks_of[0] & chunks_of[1]
    assert intel.holders == [two.id]
    assert two.label_summaries(MAP_LABELS) == from_scratch(two)


async def test_export_and_plot_read_only_the_missions_rows(
    two: Peer, table_scans: list[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    read: list[tuple[str, Any, int]] = []
    scan_labelled = two.store.scan_labelled  # type: ignore[attr-defined]

    def counting(time: int, label: str, **scope: Any) -> Any:
        rows = scan_labelled(time, label, **scope)
        read.append((label, scope.get("table"), len(rows)))
        return rows

    monkeypatch.setattr(two.store, "scan_labelled", counting)
    ops = MapOperations(two)
    exported = await ops.export_map("intel", str(tmp_path / "intel.g2o"))
    await ops.plot_map(str(tmp_path / "intel.png"), missions=["intel"])

    assert (exported["vertices"], exported["edges"]) == (1_728, 2_512)
    assert table_scans == [MISSIONS]  # the plot's choice of missions; no vertex or edge table
    per_read = {(label, table, n) for label, table, n in read}
    assert per_read == {("intel", MISSIONS, 1), ("intel", VERTICES, 1_728), ("intel", EDGES, 2_512)}


async def test_edits_and_removals_keep_the_summary_right(two: Peer) -> None:
    (far,) = await ids(two, VERTICES, "index", 5, "intel")
    loop = (await ids(two, EDGES, "kind", "LOOP", "intel"))[0]
    tx = two.begin()
    moved = Vertex(mission="intel", index=5, pose=pose_to_pb((100.0, 200.0, 0.0, 0, 0, 0, 1)))
    tx.update(VERTICES, far, moved)
    tx.remove(EDGES, loop)
    before = two.read_local(far, two.now())
    assert before is not None
    tx.insert(
        VERTICES, Vertex(mission="intel", index=99_999, pose=pose_to_pb(IDENTITY)), before.chunk_id
    )
    await tx.commit("move, remove, add")

    after = await listing(two)
    vertices, edges, box = after["intel"]
    assert (vertices, edges) == (1_729, 2_511)
    assert box is not None
    assert (box.xmax, box.ymax) == (100.0, 200.0)
    assert after["other"][:2] == (1_728, 2_512)
    assert two.label_summaries(MAP_LABELS) == from_scratch(two)

    tx = two.begin()
    tx.update(VERTICES, far, Vertex(mission="intel", index=5, pose=pose_to_pb(IDENTITY)))
    for edge in await ids(two, EDGES, "mission", "intel", "intel"):
        tx.remove(EDGES, edge)
    await tx.commit("back, and no edges")

    vertices, edges, box = (await listing(two))["intel"]
    assert (vertices, edges) == (1_729, 0)
    assert box is not None
    assert box.xmax < 100  # the box shrinks back with the vertex
    assert two.label_summaries(MAP_LABELS) == from_scratch(two)


async def test_a_conflict_resolved_by_merging_keeps_the_summary_right(two: Peer) -> None:
    (vertex,) = await ids(two, VERTICES, "index", 7, "other")
    loop = (await ids(two, EDGES, "kind", "LOOP", "other"))[0]
    ours, theirs = two.begin(), two.begin()
    theirs.update(VERTICES, vertex, Vertex(mission="other", index=7, pose=pose_to_pb(IDENTITY)))
    await theirs.commit("theirs")
    ours.update(
        VERTICES,
        vertex,
        Vertex(mission="other", index=7, pose=pose_to_pb((50.0, 0, 0, 0, 0, 0, 1))),
    )
    ours.remove(EDGES, loop)

    with pytest.raises(ConflictError) as err:
        await ours.commit("ours")
    merged = err.value.merge()  # keeps the removal; the vertex stays theirs
    await merged.commit("ours, merged")

    vertices, edges, box = (await listing(two))["other"]
    assert (vertices, edges) == (1_728, 2_511)
    assert box is not None
    assert box.xmax < 50
    assert two.label_summaries(MAP_LABELS) == from_scratch(two)


async def test_a_peer_whose_store_keeps_no_labels_reads_the_same(two: Peer) -> None:
    bare = Peer.in_memory()
    try:
        graph = read_g2o(INTEL)
        await import_graph(bare, graph)
        await import_graph(bare, graph, mission="other")
        assert await listing(bare) == await listing(two)
    finally:
        bare.store.close()
