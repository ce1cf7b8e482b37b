"""The mission summary on a peer that did not import the mission (issue 14 §2):
built as it participates in the mission's chunks one by one, kept right by the
commits the importer makes afterwards (applied here as a holder), and by
leaving a chunk."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from mapapi import Peer
from mapapi.maps import EDGES, MISSIONS, VERTICES, import_graph, list_missions, read_g2o
from mapapi.maps.labels import MAP_LABELS
from mapapi.maps.schema import Vertex, pose_to_pb
from mapapi.store.labels import summarise

from .conftest import MakePeer, lookup_swarm

INTEL = Path(__file__).resolve().parents[2] / "sample_maps" / "pose_graphs" / "intel.g2o"


def from_scratch(peer: Peer) -> list[Any]:
    """The summaries counted anew from every row held now (the oracle)."""
    store = peer.store
    return summarise(store.scan(store.clock()), MAP_LABELS, store.tables())


async def described(peer: Peer) -> list[tuple[Any, ...]]:
    return [
        (i.name, i.robot, i.vertices, i.edges, i.bbox, sorted(i.holders))
        for i in await list_missions(peer)
    ]


async def test_a_mission_imported_elsewhere_is_summarised_here_chunk_by_chunk(
    make_peer: MakePeer,
) -> None:
    a, b = await lookup_swarm(make_peer, 2)
    result = await import_graph(a, read_g2o(INTEL), robot="hahnel")

    for tile in result.tiles:
        await b.participate(tile.vertices)
    tiles = b.label_summaries(MAP_LABELS)
    assert {(s.label, s.table) for s in tiles} == {("intel", VERTICES)}
    assert [s.items for s in tiles] == [t.vertex_count for t in result.tiles]
    assert await list_missions(b) == []  # no mission row here yet

    await b.participate(result.chunks[MISSIONS])
    (info,) = await list_missions(b)
    assert (info.vertices, info.edges, info.bbox) == (1_728, 0, result.bbox)

    for tile in result.tiles:
        assert tile.edges is not None
        await b.participate(tile.edges)
    assert await described(b) == await described(a)
    assert (await described(b))[0][2:4] == (1_728, 2_512)
    assert b.label_summaries(MAP_LABELS) == from_scratch(b)


async def test_commits_of_the_importer_reach_the_summary_of_every_holder(
    make_peer: MakePeer,
) -> None:
    a, b = await lookup_swarm(make_peer, 2)
    result = await import_graph(a, read_g2o(INTEL))
    for chunk in result.all_chunks():
        await b.participate(chunk)

    tx = a.begin()
    (vertex,) = await tx.find(VERTICES, "index", 3)
    tx.update(
        VERTICES, vertex, Vertex(mission="intel", index=3, pose=pose_to_pb((90, 80, 0, 0, 0, 0, 1)))
    )
    loops = await tx.find(EDGES, "kind", "LOOP")
    for edge in list(loops)[:10]:
        tx.remove(EDGES, edge)
    await tx.commit("a vertex moved, ten loop closures dropped")
    # The commit returns once a majority appended it; b applies it when it next hears
    # from the leaders: catch its replicas up (ReadIndex), as a view begun now would.
    for chunk in result.all_chunks():
        await b.catch_up(0, chunk=chunk)

    (info,) = await list_missions(b)
    assert (info.vertices, info.edges) == (1_728, 2_502)
    assert info.bbox is not None
    assert (info.bbox.xmax, info.bbox.ymax) == (90, 80)
    assert await described(b) == await described(a)
    assert b.label_summaries(MAP_LABELS) == from_scratch(b)

    for tile in result.tiles:
        assert tile.edges is not None
        await b.leave_chunk(tile.edges)
    (info,) = await list_missions(b)
    assert (info.vertices, info.edges) == (1_728, 0)
    assert b.label_summaries(MAP_LABELS) == from_scratch(b)
