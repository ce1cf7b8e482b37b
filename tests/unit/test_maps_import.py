"""Importing pose graphs into a peer (mapapi.maps.importer): one commit per
mission, all or nothing."""

import io
from pathlib import Path

import pytest

from mapapi import Peer
from mapapi.maps import (
    EDGES,
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
from mapapi.maps.se3 import IDENTITY
from mapapi.maps.stored import mission_chunks

SAMPLES = Path(__file__).resolve().parents[2] / "sample_maps"
INTEL = SAMPLES / "pose_graphs" / "intel.g2o"


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
        assert {t: len(peer.chunks(t)) for t in (MISSIONS, VERTICES, EDGES)} == {
            MISSIONS: 1,
            VERTICES: 1,
            EDGES: 1,
        }
        assert seen[-1] == (4_241, 4_241)
        assert result.bbox == graph.bbox()

    async def test_stored_mission_reads_back_as_the_parsed_graph(self) -> None:
        peer = Peer.in_memory()
        graph = read_g2o(INTEL)
        await import_graph(peer, graph)
        back = await load_graph(peer, "intel")
        assert back.vertices == graph.vertices
        assert sorted(back.edges, key=repr) == sorted(graph.edges, key=repr)
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
        assert len(peer.chunks(VERTICES)) == 8
        tx = peer.begin()
        kinds = [e.kind for e in (await tx.items(EDGES)).values()]
        assert kinds.count(EdgeKind.INTER_ROBOT.value) == 3_548

    async def test_the_mission_row_names_the_missions_chunks(self) -> None:
        peer = Peer.in_memory()
        intel = await import_graph(peer, read_g2o(INTEL))
        tunnels = await import_graphs(peer, read_kimera(SAMPLES / "kimera_multi_tunnels_8robots"))

        named = await mission_chunks(peer, ["intel", "robot3", "nope"])

        assert named == {"intel": intel.chunks, "robot3": tunnels[3].chunks}
        assert sorted(named["intel"]) == [EDGES, MISSIONS, VERTICES]
        assert await mission_chunks(peer, []) == {}

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
        await import_graph(peer, read_g2o(INTEL, mission="first"))

        def explode(done: int, total: int) -> None:
            raise RuntimeError("stopped after staging, before the commit")

        with pytest.raises(RuntimeError, match="stopped"):
            await import_graph(peer, read_g2o(INTEL, mission="second"), progress=explode)
        assert len(peer.log()) == 1
        assert len(peer.chunks()) == 3
        assert await counts(peer) == {MISSIONS: 1, VERTICES: 1_728, EDGES: 2_512}

    async def test_a_mission_cannot_be_imported_twice(self) -> None:
        peer = Peer.in_memory()
        graph = read_g2o(INTEL)
        await import_graph(peer, graph)
        with pytest.raises(MapImportError, match="exists already"):
            await import_graph(peer, graph)
        assert len(peer.log()) == 1
        assert len(peer.chunks()) == 3

    async def test_a_table_of_another_type_is_refused(self) -> None:
        peer = Peer.in_memory()
        await peer.create_table(VERTICES, "mapapi.v1.Counter")
        with pytest.raises(MapImportError, match=r"holds mapapi\.v1\.Counter"):
            await import_graph(peer, read_g2o(INTEL))
        assert peer.log() == []
        assert set(peer.tables()) == {VERTICES}
