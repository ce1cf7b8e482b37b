"""The DGS per-robot g2o convention (issue 17 §3): GTSAM Symbol keys make one
mission per robot letter, and inter-robot edges listed in both robots' files
are kept once. Checked against the set's own merged graph, `fullGraph.g2o`,
whose plain ids are the Symbol keys' indices."""

from __future__ import annotations

import io
from collections import Counter
from pathlib import Path

import pytest

from mapapi import Peer
from mapapi.core.errors import UsageError
from mapapi.maps.dgs import per_robot, read_g2o_source, symbol
from mapapi.maps.errors import MapImportError
from mapapi.maps.g2o import parse_g2o, read_g2o
from mapapi.maps.graph import EdgeKind, MissionGraph
from mapapi.maps.operations import MapOperations
from mapapi.maps.source import detect_format

DGS = Path(__file__).resolve().parents[2] / "sample_maps" / "dgs_blocks_world_4robots_SIMULATED"
A0 = (ord("a") << 56) | 0


def _pairs(graphs: list[MissionGraph]) -> Counter[tuple[int, int]]:
    """Every edge as (source index, target index), across the missions."""
    return Counter((e.source[1], e.target[1]) for g in graphs for e in g.edges)


class TestSymbolKeys:
    def test_a_key_splits_into_letter_and_index(self) -> None:
        assert symbol(6989586621679009793) == ("a", 1)
        assert symbol(7061644215716937730) == ("b", 2)
        assert symbol(1234) is None
        assert symbol((ord("#") << 56) | 3) is None  # not a letter: a plain (huge) id

    def test_a_key_keeps_its_low_bits(self) -> None:
        """Ids are read as ints: a float would round 2^62 + 1 to 2^62."""
        text = f"VERTEX_SE2 {A0 + 1} 0 0 0\nVERTEX_SE2 {A0 + 2} 1 0 0\n"
        graph = parse_g2o(io.StringIO(text), "m", finish=False)
        assert sorted(graph.vertices) == [A0 + 1, A0 + 2]


class TestFolder:
    def test_a_folder_of_numbered_files_is_a_g2o_set(self) -> None:
        assert detect_format(DGS) == "g2o"

    def test_one_mission_per_robot_equal_to_the_merged_graph(self) -> None:
        graphs = read_g2o_source(DGS, None, None)
        full = read_g2o(DGS / "fullGraph.g2o")

        assert [(g.name, g.robot, len(g.vertices)) for g in graphs] == [
            ("robot-a", "a", 16),
            ("robot-b", "b", 16),
            ("robot-c", "c", 16),
            ("robot-d", "d", 16),
        ]
        for graph in graphs:
            assert all(full.vertices[i] == pose for i, pose in graph.vertices.items())
        assert _pairs(graphs) == _pairs([full])  # each inter-robot edge once: 144 in all
        kinds = Counter(e.kind for g in graphs for e in g.edges)
        assert kinds[EdgeKind.INTER_ROBOT] == 32

    def test_an_inter_robot_edge_is_owned_by_its_source_robot(self) -> None:
        for graph in read_g2o_source(DGS, "blocks-", None):
            assert graph.name.startswith("blocks-")
            assert all(e.source[0] == graph.name for e in graph.edges)

    def test_files_imported_one_by_one_keep_each_edge_once(self) -> None:
        alone = [g for n in range(4) for g in read_g2o_source(DGS / f"{n}.g2o", None, None)]
        assert [g.name for g in alone] == ["robot-a", "robot-b", "robot-c", "robot-d"]
        assert _pairs(alone) == _pairs(read_g2o_source(DGS, None, None))

    def test_robot_is_refused_for_several_missions(self) -> None:
        with pytest.raises(UsageError, match="drop --robot"):
            read_g2o_source(DGS, None, "husky")


class TestPlainAndMixed:
    def test_a_plain_graph_stays_one_mission(self) -> None:
        (graph,) = read_g2o_source(DGS / "fullGraph.g2o", None, None)
        assert (graph.name, len(graph.vertices), len(graph.edges)) == ("fullGraph", 64, 144)

    def test_one_plain_id_makes_the_file_a_plain_graph(self, tmp_path: Path) -> None:
        mixed = tmp_path / "mixed.g2o"
        mixed.write_text(f"VERTEX_SE2 {A0} 0 0 0\nVERTEX_SE2 5 1 0 0\n")
        (graph,) = read_g2o_source(mixed, None, None)
        assert sorted(graph.vertices) == [5, A0]

    def test_landmarks_keyed_by_robot_are_refused(self) -> None:
        text = f"VERTEX_SE2 {A0} 0 0 0\nVERTEX_XY {A0 + 1} 1 0\n"
        parsed = parse_g2o(io.StringIO(text), "m", finish=False)
        with pytest.raises(MapImportError, match="no landmarks"):
            per_robot([(parsed, "x.g2o")], "robot-")


async def test_the_set_imports_into_a_repository(make_peer) -> None:  # type: ignore[no-untyped-def]
    peer: Peer = await make_peer()
    ops = MapOperations(peer)
    info = await ops.imports.import_map(str(DGS), mission="blocks-")
    assert [m["name"] for m in info["missions"]] == [f"blocks-{c}" for c in "abcd"]
    assert info["elements"] == 64 + 144

    listed = {m["name"]: (m["vertices"], m["edges"]) for m in (await ops.missions())["missions"]}
    assert listed == {
        "blocks-a": (16, 44),
        "blocks-b": (16, 36),
        "blocks-c": (16, 36),
        "blocks-d": (16, 28),
    }
