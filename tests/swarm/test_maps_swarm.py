"""Imported missions in the spatial index (issue 5 §1): a graph or a point cloud
imported on one peer is found by its box from another, which can then load it.

Every peer is a real node of a settled Chord ring (`lookup_swarm`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mapapi import Peer
from mapapi.lookup.spatial import BBox
from mapapi.maps import (
    CLOUDS,
    FRAMES,
    MISSIONS,
    VERTICES,
    import_cloud,
    import_graph,
    import_missions,
    list_missions,
    load_cloud,
    read_g2o,
)
from mapapi.maps.cloud_file import read_cloud
from mapapi.maps.operations import MapOperations
from mapapi.service.transfer_ops import SwarmOperations

from .conftest import MakePeer, lookup_swarm

SAMPLES = Path(__file__).resolve().parents[2] / "sample_maps"
INTEL = SAMPLES / "pose_graphs" / "intel.g2o"  # x -9.5..15.9, y -22.5..3.4, z 0
GARAGE = SAMPLES / "pose_graphs" / "parking-garage.g2o"
ROOM = SAMPLES / "point_clouds" / "room_scan1.pcd"  # x -13.8..15.4, y -6.5..8.0


async def found_by_table(peer: Peer, box: BBox) -> dict[str, list[tuple[str, ...]]]:
    """table -> the missions of each chunk `peer` finds in `box`."""
    out: dict[str, list[tuple[str, ...]]] = {}
    for hit in await peer.query_bbox(box):
        out.setdefault(hit.ref.table, []).append(hit.ref.missions)
    return out


async def test_an_imported_graph_is_found_by_its_mission_box_elsewhere(
    make_peer: MakePeer,
) -> None:
    a, b, c = await lookup_swarm(make_peer, 3)
    result = await import_graph(a, read_g2o(INTEL), robot="hahnel")

    hits = await c.query_bbox(BBox(10, -20, -1, 11, -19, 1), table=MISSIONS)

    (hit,) = hits
    assert hit.ref.missions == ("intel",)
    assert hit.ref.chunk == result.chunks[MISSIONS]
    assert hit.ref.bbox == result.bbox
    assert ([m.id for m in hit.holders], hit.held) == ([a.id], False)
    # the vertices are placed too, each tile by its box (labelled with their
    # mission); the edges, which have no place, are not
    assert await found_by_table(b, BBox(-100, -100, -10, 100, 100, 10)) == {
        MISSIONS: [("intel",)],
        VERTICES: [("intel",)] * len(result.tiles),
    }
    assert await c.query_bbox(BBox(50, 50, -1, 60, 60, 1)) == []

    await c.participate(hit.ref.chunk)
    (info,) = await list_missions(c)
    assert (info.name, info.robot, info.bbox) == ("intel", "hahnel", result.bbox)
    assert sorted(info.holders) == sorted([a.id, c.id])


async def test_a_point_cloud_is_found_and_loaded_from_another_peer(make_peer: MakePeer) -> None:
    a, b = await lookup_swarm(make_peer, 2)
    cloud = read_cloud(ROOM, voxel=0.2)
    result = await import_cloud(a, cloud)

    hits = await b.query_bbox(BBox(14, 7, 0, 20, 20, 1))

    assert {h.ref.table: h.ref.missions for h in hits} == {
        MISSIONS: ("room_scan1",),
        CLOUDS: ("room_scan1",),
    }
    for hit in hits:
        await b.participate(hit.ref.chunk)
    loaded = await load_cloud(b, "room_scan1")
    assert len(loaded.points) == result.points == len(cloud.points)
    assert np.array_equal(np.sort(loaded.points, axis=0), np.sort(cloud.points, axis=0))


async def test_missions_with_swarm_lists_what_others_hold(make_peer: MakePeer) -> None:
    a, b = await lookup_swarm(make_peer, 2)
    await import_graph(a, read_g2o(INTEL))
    await import_cloud(b, read_cloud(ROOM, voxel=0.5))

    here = await MapOperations(b).missions()
    everywhere = await MapOperations(b).missions(swarm=True)

    assert [m["name"] for m in here["missions"]] == ["room_scan1"]
    intel, room = everywhere["missions"]
    assert (intel["name"], intel["held"], intel["vertices"]) == ("intel", False, None)
    assert intel["holders"] == [{"id": a.id, "name": a.name, "address": a.address}]
    assert (room["name"], room["held"], room["holders"][0]["id"]) == ("room_scan1", True, b.id)


async def test_load_bbox_loads_the_mission_row_and_the_tiles_in_the_box(
    make_peer: MakePeer, tmp_path: Path
) -> None:
    a, b = await lookup_swarm(make_peer, 2)
    result = await import_graph(a, read_g2o(GARAGE), mission="garage")  # in 12 tiles
    ops = MapOperations(b)
    corner = result.tiles[0].bbox.mins  # a vertex's spot, with a centimetre around it
    box = [*(v - 0.01 for v in corner), *(v + 0.01 for v in corner)]
    (inside,) = [t for t in result.tiles if t.bbox.overlaps(BBox.from_tuple(box))]
    outside = [t for t in result.tiles if t is not inside]
    assert len(outside) == 11

    loaded = await ops.load_bbox(box)

    # the box finds the row and the tile's vertices; the row names the tile's edges
    # and the mission's frames (empty until `align`: they come along for world reads)
    assert sorted(c["chunk"] for c in loaded["loaded"]) == sorted(
        [result.chunks[MISSIONS], result.chunks[FRAMES], *inside.chunks()]
    )
    assert {r["table"]: r["held"] for r in loaded["results"]} == {MISSIONS: True, VERTICES: True}
    items = {c["chunk"]: c["items"] for c in loaded["loaded"]}
    assert (items[inside.vertices], items[inside.edges]) == (
        inside.vertex_count,
        inside.edge_count,
    )
    assert loaded["items"] == 1 + inside.vertex_count + inside.edge_count
    sizes = {c.id: c.bytes for c in a.chunks()}
    assert loaded["bytes"] == sum(sizes[c["chunk"]] for c in loaded["loaded"]) > 0
    (info,) = await list_missions(b)
    assert (info.vertices, info.edges) == (inside.vertex_count, inside.edge_count)
    # what is held exports and draws: edges to vertices of tiles not held are left out
    part = await ops.export_map("garage", str(tmp_path / "part.g2o"))
    assert part["vertices"] == inside.vertex_count
    assert part["edges"] + part["left_out"] == inside.edge_count
    assert part["left_out"] > 0  # the tile's edges across its border
    assert read_g2o(tmp_path / "part.g2o").elements() == part["vertices"] + part["edges"]
    await ops.plot_map(str(tmp_path / "part.png"), missions=["garage"])
    assert (tmp_path / "part.png").stat().st_size > 0
    assert await ops.load_progress(box) == {"loaded": 0, "of": 0}
    again = await ops.load_bbox(box)
    assert (again["loaded"], again["items"], again["bytes"]) == ([], 0, 0)

    assert result.bbox is not None
    everything = await ops.load_bbox(list(result.bbox.as_tuple()))
    assert sorted(c["chunk"] for c in everything["loaded"]) == sorted(
        c for t in outside for c in t.chunks()
    )
    (info,) = await list_missions(b)
    assert (info.vertices, info.edges) == (1_661, 6_275)


async def test_traffic_counts_what_the_transport_moved(make_peer: MakePeer) -> None:
    a, b = await lookup_swarm(make_peer, 2)
    await import_graph(a, read_g2o(INTEL))
    before = await SwarmOperations(b).traffic()

    await MapOperations(b).load_bbox([-100, -100, -1, 100, 100, 1])

    after = await SwarmOperations(b).traffic()
    received = after["received"]["bytes"] - before["received"]["bytes"]
    assert received > 2_512 * 21 * 8  # at least the edges' information matrices
    assert sum(after["received_by_type"].values()) == after["received"]["bytes"]
    assert after["sent"]["messages"] > before["sent"]["messages"]


async def test_a_mission_exports_the_same_bytes_on_another_peer(
    make_peer: MakePeer, tmp_path: Path
) -> None:
    """Issue 15: the same mission gives the same bytes on any peer, in the
    order and number formatting of the file it was imported from."""
    a, b = await lookup_swarm(make_peer, 2)
    await MapOperations(a).imports.import_map(str(INTEL))
    loaded = await MapOperations(b).load_bbox([-100, -100, -10, 100, 100, 10])
    assert loaded["loaded"]

    await MapOperations(a).export_map("intel", str(tmp_path / "a.g2o"))
    await MapOperations(b).export_map("intel", str(tmp_path / "b.g2o"))

    assert (tmp_path / "b.g2o").read_bytes() == (tmp_path / "a.g2o").read_bytes()
    assert (tmp_path / "b.g2o").read_bytes() == INTEL.read_bytes()


async def test_a_grid_is_found_loaded_and_written_by_another_peer(
    make_peer: MakePeer, tmp_path: Path
) -> None:
    from mapapi.maps.grid_ops import GridOperations
    from mapapi.maps.occupancy import OccupancyGrid, nav2_pixels
    from mapapi.maps.schema import GRIDS

    a, b = await lookup_swarm(make_peer, 2)
    cells = (np.arange(300 * 100) % 102 - 1).astype(np.int8).reshape(100, 300)  # two tiles
    grid = OccupancyGrid("floor", "r1", "floor/map", 0.05, -2.0, 1.0, 0.0, cells)
    (result,) = await import_missions(a, [grid])
    found = await found_by_table(b, BBox(-1, 2, -1, 1, 3, 1))
    assert found[GRIDS] == [("floor",)]

    loaded = await MapOperations(b).load_bbox([-1, 2, -1, 1, 3, 1])
    assert sorted(c["chunk"] for c in loaded["loaded"]) == sorted(result.all_chunks())
    info = await GridOperations(b).grid_map(str(tmp_path / "floor.yaml"), ["floor"])
    assert (info["width"], info["height"], info["origin"]) == (300, 100, [-2.0, 1.0, 0.0])
    image = (tmp_path / "floor.pgm").read_bytes()
    assert image.endswith(nav2_pixels(cells).tobytes())
