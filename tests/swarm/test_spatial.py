"""The spatial index over the ring (DESIGN §7, issue 4 §3): chunk boxes announced
at commit, queries with exact filtering at the cell owner, clamping, the index
geometry checked at join.

Every peer is a real node of the Chord ring on its swarm endpoint; each test
waits until the ring agrees with the `SortedRing` oracle, so every entry lands
at its cell's real owner.
"""

from __future__ import annotations

import pytest
from google.protobuf import struct_pb2

from mapapi import ChunkId, Peer
from mapapi._pb.mapapi.v1 import maps_pb2
from mapapi.core.errors import InvalidBBox, JoinRefused, ProtocolError
from mapapi.core.ids import ItemId
from mapapi.lookup.spatial import BBox, SpatialGrid
from mapapi.lookup.spatial_index import QueryStats, SpatialRef, encode_filter

from .conftest import FAST, MakePeer, lookup_swarm, net

ROOMS = "rooms"


def room(*bbox: float, name: str = "") -> struct_pb2.Struct:
    """A schemaless item placed by its "bbox" field."""
    item = struct_pb2.Struct()
    item.update({"bbox": list(bbox), "name": name})
    return item


async def rooms_chunk(peer: Peer) -> ChunkId:
    if ROOMS not in peer.tables():
        await peer.create_table(ROOMS, "google.protobuf.Struct")
    return await peer.create_chunk(ROOMS)


async def put(peer: Peer, chunk: ChunkId, *items: struct_pb2.Struct) -> list[ItemId]:
    tx = peer.begin()
    ids = [tx.insert(ROOMS, item, chunk) for item in items]
    assert await tx.commit("rooms") is not None
    return ids


def chunks(refs: list[SpatialRef]) -> set[ChunkId]:
    return {r.chunk for r in refs}


async def found(peer: Peer, *bbox: float, table: str | None = None) -> set[ChunkId]:
    return {p.ref.chunk for p in await peer.query_bbox(BBox(*bbox), table)}


async def test_a_peer_that_never_saw_a_chunk_finds_it_by_box_and_loads_it(
    make_peer: MakePeer,
) -> None:
    a, b, c = await lookup_swarm(make_peer, 3)
    kitchen = await rooms_chunk(a)
    (item,) = await put(a, kitchen, room(0, 0, 0, 5, 4, 3, name="kitchen"))

    hits = await c.query_bbox(BBox(4, 3, 0, 6, 6, 1))

    assert [h.ref.chunk for h in hits] == [kitchen]
    (hit,) = hits
    assert (hit.ref.table, hit.ref.bbox) == (ROOMS, BBox(0, 0, 0, 5, 4, 3))
    assert ([m.id for m in hit.holders], hit.held) == ([a.id], False)
    assert hit.holders[0].address == a.address
    await c.participate(hit.ref.chunk)
    tx = c.begin()
    assert (await tx.get(ROOMS, item))["name"] == "kitchen"
    assert await found(b, 100, 100, 0, 101, 101, 1) == set()


async def test_the_cell_owner_filters_by_exact_overlap(make_peer: MakePeer) -> None:
    # default cells are 64 m wide: both rooms lie in cell (16, 16), only one in the box
    a, b = await lookup_swarm(make_peer, 2)
    near, far = await rooms_chunk(a), await rooms_chunk(a)
    await put(a, near, room(1, 1, 0, 2, 2, 1))
    await put(a, far, room(40, 40, 0, 41, 41, 1))
    index = net(b).index
    assert index is not None
    box = BBox(0.5, 0.5, 0, 3, 3, 1)
    assert len(index.grid.cells_overlapping(box)) == 1

    exact, everything = QueryStats(), QueryStats()
    assert chunks(await index.query(box, stats=exact)) == {near}
    assert chunks(await index.query(box, exact_at_owner=False, stats=everything)) == {near}

    assert (exact.cells, exact.transferred) == (1, 1)
    assert (everything.cells, everything.transferred) == (1, 2)


async def test_a_grown_box_replaces_its_entry_and_a_shrunk_one_is_tightened_at_refresh(
    make_peer: MakePeer,
) -> None:
    a, b = await lookup_swarm(make_peer, 2)
    chunk = await rooms_chunk(a)
    await put(a, chunk, room(1, 1, 0, 2, 2, 1))
    (far,) = await put(a, chunk, room(300, 300, 0, 301, 301, 1))
    index = net(b).index
    assert index is not None

    assert await found(b, 299, 299, 0, 302, 302, 1) == {chunk}
    (ref,) = await index.query(BBox(0, 0, 0, 3, 3, 1))
    assert ref.bbox == BBox(1, 1, 0, 301, 301, 1)
    everything = QueryStats()
    await index.query(BBox(0, 0, 0, 3, 3, 1), exact_at_owner=False, stats=everything)
    assert everything.transferred == 1  # the small box's entry was withdrawn

    tx = a.begin()
    tx.remove(ROOMS, far)
    await tx.commit("the far room goes")
    assert await found(b, 299, 299, 0, 302, 302, 1) == {chunk}  # loose until the refresh
    await net(a).places.announced.refresh()  # type: ignore[union-attr]
    assert await found(b, 299, 299, 0, 302, 302, 1) == set()
    assert await found(b, 0, 0, 0, 3, 3, 1) == {chunk}


async def test_each_holder_keeps_its_own_entry(make_peer: MakePeer) -> None:
    a, b, c = await lookup_swarm(make_peer, 3)
    chunk = await rooms_chunk(a)
    await put(a, chunk, room(1, 1, 0, 2, 2, 1))
    await b.participate(chunk)

    (hit,) = await c.query_bbox(BBox(0, 0, 0, 3, 3, 1))
    assert {m.id for m in hit.holders} == {a.id, b.id}

    await b.leave_chunk(chunk)
    (hit,) = await c.query_bbox(BBox(0, 0, 0, 3, 3, 1))
    assert [m.id for m in hit.holders] == [a.id]


async def test_missions_are_listed_by_name(make_peer: MakePeer) -> None:
    a, b = await lookup_swarm(make_peer, 2)
    await a.create_table("missions", "mapapi.v1.Mission")
    chunk = await a.create_chunk("missions")
    tx = a.begin()
    box = maps_pb2.Box3(xmin=-10, ymin=-5, zmin=0, xmax=20, ymax=8, zmax=2)
    tx.insert("missions", maps_pb2.Mission(name="tunnel-a", robot="acl_jackal", bbox=box), chunk)
    await tx.commit("a mission")

    (hit,) = await b.query_bbox(BBox(19, 7, 1, 30, 30, 1), table="missions")
    assert hit.ref.missions == ("tunnel-a",)
    assert await found(b, 19, 7, 1, 30, 30, 1, table=ROOMS) == set()


async def test_boxes_at_and_beyond_the_bounds(make_peer: MakePeer) -> None:
    grid = SpatialGrid(BBox(0, 0, 0, 100, 100, 10), (4, 4, 1))
    a, b = await lookup_swarm(make_peer, 2, spatial=grid)
    edge = await rooms_chunk(a)
    await put(a, edge, room(90, 90, 0, 150, 95, 1))  # partly outside: clamped
    index = net(b).index
    assert index is not None

    assert await found(b, 95, 80, 0, 500, 500, 5) == {edge}
    stats = QueryStats()
    assert await index.query(BBox(200, 200, 0, 300, 300, 1), stats=stats) == []
    assert (stats.cells, stats.requests) == (0, 0)
    assert await found(b, 120, 90, 0, 130, 95, 1) == set()  # overlaps only outside
    with pytest.raises(InvalidBBox):
        BBox(1, 0, 0, 0, 1, 1)


async def test_a_peer_with_another_index_geometry_is_refused(make_peer: MakePeer) -> None:
    (a,) = await lookup_swarm(make_peer, 1)
    stranger = await make_peer(spatial=SpatialGrid(cells=(16, 16, 1)))
    await stranger.start("tcp://127.0.0.1:0", chord=FAST)

    with pytest.raises(JoinRefused, match=r"spatial index differs.*cells 32x32x1"):
        await stranger.join(a.address)
    assert [m.id for m in a.members()] == []


async def test_the_owner_refuses_an_unknown_filter_or_a_bad_argument(make_peer: MakePeer) -> None:
    _, b = await lookup_swarm(make_peer, 2)
    chord = net(b).chord
    key = net(b).grid.cell_key(0, "chunks")
    with pytest.raises(ProtocolError, match="no member filter 'sql'"):
        await chord.get(key, "sql", b"DROP TABLE")
    with pytest.raises(ProtocolError, match="bad argument to filter 'bbox'"):
        await chord.get(key, "bbox", b"\xff\xff")
    assert await chord.get(key, "bbox", encode_filter(BBox(0, 0, 0, 1, 1, 1))) == set()
