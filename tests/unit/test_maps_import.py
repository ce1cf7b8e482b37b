"""Importing pose graphs into a peer (mapapi.maps.importer): one commit per
mission, all or nothing."""

import io
from pathlib import Path

import pytest

from mapapi import Peer
from mapapi.lookup.spatial import BBox
from mapapi.maps import (
    EDGES,
    FRAMES,
    MISSIONS,
    VERTICES,
    EdgeKind,
    GraphEdge,
    MapImportError,
    MissionGraph,
    import_graph,
    import_graphs,
    load_graph,
    parse_g2o,
    read_g2o,
    read_kimera,
)
from mapapi.maps.g2o_records import lean_edge
from mapapi.maps.se3 import IDENTITY
from mapapi.maps.stored import mission_parts

SAMPLES = Path(__file__).resolve().parents[2] / "sample_maps"
INTEL = SAMPLES / "pose_graphs" / "intel.g2o"
GARAGE = SAMPLES / "pose_graphs" / "parking-garage.g2o"


async def counts(peer: Peer) -> dict[str, int]:
    tx = peer.begin()
    found = {t: len(await tx.items(t)) for t in (MISSIONS, VERTICES, EDGES) if t in peer.tables()}
    tx.abort()
    return found


class TestImportGraph:
    async def test_intel_is_one_commit_with_every_row(self) -> None:
        peer = Peer.in_memory()
        graph = read_g2o(INTEL)
        seen: list[tuple[int, int]] = []

        result = await import_graph(
            peer, graph, robot="hahnel", progress=lambda d, t: seen.append((d, t))
        )

        assert len(peer.log()) == 1
        assert peer.log()[0].id == result.commit
        assert (result.mission, result.robot, result.vertices, result.edges) == (
            "intel",
            "hahnel",
            1_728,
            2_512,
        )
        assert await counts(peer) == {MISSIONS: 1, VERTICES: 1_728, EDGES: 2_512}
        # 1,728 vertices in 26 m: 4 tiles (at most TILE_VERTICES each, TILE_EXTENT wide)
        assert len(result.tiles) == 4
        assert {t: len(peer.chunks(t)) for t in (MISSIONS, VERTICES, EDGES)} == {
            MISSIONS: 1,
            VERTICES: 4,
            EDGES: 4,
        }
        assert [t.vertex_count for t in result.tiles] == [432] * 4
        assert sum(t.edge_count for t in result.tiles) == 2_512
        held = {c.id: c.items for c in peer.chunks()}
        for tile in result.tiles:
            assert (held[tile.vertices], held[tile.edges]) == (tile.vertex_count, tile.edge_count)
        assert seen[-1] == (4_241, 4_241)
        assert result.bbox == graph.bbox()

    async def test_stored_mission_reads_back_as_the_parsed_graph(self) -> None:
        peer = Peer.in_memory()
        graph = read_g2o(INTEL)
        await import_graph(peer, graph)
        back = await load_graph(peer, "intel")
        assert back.vertices == graph.vertices
        # a row keeps a line's number formatting in place of its text where that
        # writes it again (`lean_edge`): in intel.g2o, each line without a number
        # in exponent form (2,468 of 2,512 edges)
        lean = [lean_edge(e, graph.planar) for e in graph.edges]
        for kept, read in zip(lean, graph.edges, strict=True):
            assert bool(kept.origin.text) == ("e" in read.origin.text.partition(" ")[2])
        assert sorted(back.edges, key=repr) == sorted(lean, key=repr)
        tx = peer.begin()
        (row,) = (await tx.items(MISSIONS)).values()
        box = graph.bbox()
        assert box is not None
        assert (row.bbox.xmin, row.bbox.ymax, row.frame) == (box.xmin, box.ymax, "intel/map")

    async def test_tunnels_make_one_commit_per_robot(self) -> None:
        peer = Peer.in_memory()
        graphs = read_kimera(SAMPLES / "kimera_multi_tunnels_8robots")

        results = await import_graphs(peer, graphs)

        assert len(peer.log()) == 8 == len({r.commit for r in results})
        assert await counts(peer) == {MISSIONS: 8, VERTICES: 1_255, EDGES: 1_247 + 96 + 3_548}
        # each robot's path has fewer poses than TILE_MIN_VERTICES: not cut, however long
        assert len(peer.chunks(VERTICES)) == 8 == sum(len(r.tiles) for r in results)
        tx = peer.begin()
        kinds = [e.kind for e in (await tx.items(EDGES)).values()]
        assert kinds.count(EdgeKind.INTER_ROBOT.value) == 3_548

    async def test_the_mission_row_names_the_missions_chunks_and_tiles(self) -> None:
        peer = Peer.in_memory()
        intel = await import_graph(peer, read_g2o(INTEL))
        tunnels = await import_graphs(peer, read_kimera(SAMPLES / "kimera_multi_tunnels_8robots"))

        named = await mission_parts(peer, ["intel", "robot3", "nope"])

        assert set(named) == {"intel", "robot3"}
        assert named["intel"].chunks == intel.chunks
        assert set(intel.chunks) == {MISSIONS, FRAMES}  # the graph is in tiles
        assert named["intel"].tiles == intel.tiles
        assert named["robot3"].tiles == tunnels[3].tiles
        every = {c.id for c in peer.chunks()}
        assert set(intel.all_chunks()) | set(tunnels[3].all_chunks()) <= every
        assert await mission_parts(peer, []) == {}

    async def test_a_box_needs_the_mission_row_and_the_tiles_it_overlaps(self) -> None:
        peer = Peer.in_memory()
        garage = await import_graph(peer, read_g2o(GARAGE))  # 1,661 poses over 270 m: 12 tiles
        first, *others = garage.tiles
        (parts,) = (await mission_parts(peer, ["parking-garage"])).values()

        assert len(others) == 11
        assert parts.in_box(first.bbox) >= {garage.chunks[MISSIONS], *first.chunks()}
        inside = BBox(*first.bbox.mins, *first.bbox.mins)  # a corner of the first tile only
        assert not any(t.bbox.overlaps(inside) for t in others)
        # the mission's row and frames, and the one tile
        assert parts.in_box(inside) == {*garage.chunks.values(), *first.chunks()}
        # a tile the index found in the box (a vertex moved there) comes with its edges
        moved = others[0]
        assert set(moved.chunks()) <= parts.in_box(inside, {moved.vertices})
        assert garage.bbox is not None
        assert parts.in_box(garage.bbox) == set(garage.all_chunks())

    async def test_renaming_moves_the_missions_own_edge_ends(self) -> None:
        peer = Peer.in_memory()
        graph = parse_g2o(io.StringIO("EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\n"), "a")
        await import_graph(peer, graph, mission="b")
        back = await load_graph(peer, "b")
        assert back.edges[0].source == ("b", 0)
        assert back.edges[0].target == ("b", 1)


class TestNothingHalfImported:
    async def test_an_edge_to_a_missing_vertex_commits_nothing(self) -> None:
        peer = Peer.in_memory()
        graph = MissionGraph("m", vertices={0: IDENTITY})
        graph.edges.append(GraphEdge(("m", 0), ("m", 7), IDENTITY, (0.0,) * 21, EdgeKind.LOOP))
        with pytest.raises(MapImportError, match="missing vertex 7"):
            await import_graph(peer, graph)
        assert peer.log() == []
        assert peer.chunks() == []

    async def test_a_failure_while_staging_leaves_no_rows_and_no_chunks(self) -> None:
        peer = Peer.in_memory()
        first = await import_graph(peer, read_g2o(INTEL, mission="first"))

        def explode(done: int, total: int) -> None:
            raise RuntimeError("stopped after staging, before the commit")

        with pytest.raises(RuntimeError, match="stopped"):
            await import_graph(peer, read_g2o(INTEL, mission="second"), progress=explode)
        assert len(peer.log()) == 1
        assert sorted(c.id for c in peer.chunks()) == sorted(first.all_chunks())
        assert await counts(peer) == {MISSIONS: 1, VERTICES: 1_728, EDGES: 2_512}

    async def test_a_mission_cannot_be_imported_twice(self) -> None:
        peer = Peer.in_memory()
        graph = read_g2o(INTEL)
        first = await import_graph(peer, graph)
        with pytest.raises(MapImportError, match="exists already"):
            await import_graph(peer, graph)
        assert len(peer.log()) == 1
        assert sorted(c.id for c in peer.chunks()) == sorted(first.all_chunks())

    async def test_a_table_of_another_type_is_refused(self) -> None:
        peer = Peer.in_memory()
        await peer.create_table(VERTICES, "mapapi.v1.Counter")
        with pytest.raises(MapImportError, match=r"holds mapapi\.v1\.Counter"):
            await import_graph(peer, read_g2o(INTEL))
        assert peer.log() == []
        assert set(peer.tables()) == {VERTICES}
