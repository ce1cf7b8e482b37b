"""Where a chunk lies (mapapi.lookup.chunk_places): a store that keeps the map
tables' labels answers from its summaries exactly what reading every item
answers, and boxes computed off the event loop still hold the commits applied
while they were computed (issue 14 §1)."""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable
from pathlib import Path

import numpy as np

from mapapi import Peer
from mapapi.lookup import chunk_places
from mapapi.maps import PointCloud, import_cloud, import_graph, read_g2o
from mapapi.maps.schema import CLOUDS, VERTICES, Vertex, pose_to_pb
from mapapi.maps.se3 import IDENTITY

SAMPLES = Path(__file__).resolve().parents[2] / "sample_maps"

MakePeer = Callable[..., Awaitable[Peer]]


def by_reading(peer: Peer) -> dict[str, object]:
    """Every chunk's place, computed by reading and decoding its items."""
    return {c.id: chunk_places._compute(peer.store, c.id, None) for c in peer.chunks()}


async def test_summaries_place_chunks_as_reading_their_items_does(make_peer: MakePeer) -> None:
    peer = await make_peer()
    await import_graph(peer, read_g2o(SAMPLES / "pose_graphs" / "intel.g2o"))
    await import_graph(peer, read_g2o(SAMPLES / "pose_graphs" / "parking-garage.g2o"))
    points = np.random.default_rng(3).uniform([-5, -5, 0], [5, 5, 2], size=(3_000, 3))
    await import_cloud(peer, PointCloud("scan", points=points.astype(np.float32)))
    tx = peer.begin()  # a vertex moved far away, a block of points removed
    vertices = await tx.items(VERTICES)
    moved = sorted(vertices)[0]
    far = Vertex()
    far.CopyFrom(vertices[moved])
    far.pose.CopyFrom(pose_to_pb((900.0, -900.0, 3.0, *IDENTITY[3:])))
    tx.update(VERTICES, moved, far)
    tx.remove(CLOUDS, sorted(await tx.items(CLOUDS))[0])
    await tx.commit("move and remove")

    summarised = chunk_places._compute_all(peer.store, [c.id for c in peer.chunks()])

    assert summarised == by_reading(peer)
    assert any(ref is not None and ref.bbox.xmax == 900.0 for ref in summarised.values())


async def test_a_box_computed_off_the_loop_holds_what_was_applied_meanwhile(
    make_peer: MakePeer,
) -> None:
    peer = await make_peer()
    imported = await import_graph(peer, read_g2o(SAMPLES / "pose_graphs" / "intel.g2o"))
    chunk = imported.tiles[0].vertices
    places = peer.places
    places.forget(chunk)
    tx = peer.begin()
    vertex = next(iter((await tx.items(VERTICES)).values()))
    far = Vertex()
    far.CopyFrom(vertex)
    far.index = 99_999
    far.pose.CopyFrom(pose_to_pb((700.0, 700.0, 0.0, *IDENTITY[3:])))
    tx.insert(VERTICES, far, chunk)

    warming = asyncio.ensure_future(places.warm([chunk]))  # computes in a worker thread
    await asyncio.sleep(0)  # sync-ok: a yield; the commit below lands before or after its read
    await tx.commit("a vertex far away, while the box is computed")
    await warming

    ref = places.ref(chunk)
    assert ref is not None
    assert ref.bbox.xmax == 700.0
    assert ref == by_reading(peer)[chunk]
