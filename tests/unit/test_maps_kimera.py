"""The Kimera-Multi 8-robot CSV (mapapi.maps.kimera), on the shipped tunnels set."""

import io
import shutil
from dataclasses import replace
from pathlib import Path

import pytest

from mapapi.maps import EdgeKind, KimeraReader, MapImportError, parse_g2o, read_kimera, write_g2o
from mapapi.maps.graph import NO_ORIGIN
from mapapi.maps.kimera import HEADER

TUNNELS = Path(__file__).resolve().parents[2] / "sample_maps" / "kimera_multi_tunnels_8robots"


@pytest.fixture(scope="module")
def graphs() -> list:
    return read_kimera(TUNNELS)


class TestTunnelsCounts:
    def test_one_mission_per_robot_with_the_readme_pose_counts(self, graphs: list) -> None:
        assert [g.name for g in graphs] == [f"robot{i}" for i in range(8)]
        assert [len(g.vertices) for g in graphs] == [105, 138, 149, 148, 168, 175, 191, 181]
        assert sum(len(g.vertices) for g in graphs) == 1_255

    def test_edge_counts_match_the_readme(self, graphs: list) -> None:
        assert sum(g.count(EdgeKind.ODOMETRY) for g in graphs) == 1_247
        assert sum(g.count(EdgeKind.LOOP) for g in graphs) == 96
        assert sum(g.count(EdgeKind.INTER_ROBOT) for g in graphs) == 3_548

    def test_inter_robot_edges_are_distinct_and_owned_by_the_source_robot(
        self, graphs: list
    ) -> None:
        inter = [(g.name, e) for g in graphs for e in g.edges if e.kind is EdgeKind.INTER_ROBOT]
        assert len({(e.source, e.target) for _, e in inter}) == len(inter)
        assert all(owner == e.source[0] != e.target[0] for owner, e in inter)

    def test_trajectories_are_dead_reckoned_hundreds_of_metres(self, graphs: list) -> None:
        for graph in graphs:
            assert graph.vertices[0] == (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
            box = graph.bbox()
            assert box is not None
            assert max(box.xmax - box.xmin, box.zmax - box.zmin) > 20

    def test_prefix_names_the_missions(self) -> None:
        reader = KimeraReader(prefix="tunnels-")
        reader.read(io.StringIO(",".join(HEADER) + "\n0,0,0,1,0,0,0,1,1,0,0,100,10,1,1\n"))
        (graph,) = reader.graphs()
        assert (graph.name, graph.robot, len(graph.vertices)) == ("tunnels-robot0", "robot0", 2)
        assert graph.edges[0].information[0] == 10  # tau on x
        assert graph.edges[0].information[-1] == 200  # 2 kappa on rz


class TestMalformed:
    def test_a_wrong_header_is_refused(self) -> None:
        with pytest.raises(MapImportError, match=r"f\.csv:1: expected the header"):
            KimeraReader().read(io.StringIO("a,b,c\n"), "f.csv")

    @pytest.mark.parametrize(
        ("row", "match"),
        [
            ("0,0,0,1,0,0,0,1,1,0,0,100,10,1", "expected 15 columns, found 14"),
            ("0,x,0,1,0,0,0,1,1,0,0,100,10,1,1", "not a number"),
            ("0,0,0,1,0,0,0,3,1,0,0,100,10,1,1", "not a unit"),
            ("0,0,0,1,0,0,0,1,inf,0,0,100,10,1,1", "finite"),
        ],
    )
    def test_a_bad_row_names_its_line(self, row: str, match: str) -> None:
        text = ",".join(HEADER) + "\n0,0,0,1,0,0,0,1,1,0,0,100,10,1,1\n" + row + "\n"
        with pytest.raises(MapImportError, match=match) as caught:
            KimeraReader().read(io.StringIO(text), "f.csv")
        assert caught.value.line == 3

    def test_a_broken_sample_file_names_file_and_line(self, tmp_path: Path) -> None:
        copy = tmp_path / "tunnels"
        shutil.copytree(TUNNELS, copy)
        target = copy / "robot3" / "measurements.csv"
        lines = target.read_text().splitlines(keepends=True)
        lines[41] = "3,40,3,41,oops\n"
        target.write_text("".join(lines))
        with pytest.raises(MapImportError, match=r"robot3/measurements\.csv:42: expected 15"):
            read_kimera(copy)

    def test_a_folder_without_robots_is_refused(self, tmp_path: Path) -> None:
        with pytest.raises(MapImportError, match="no robot"):
            read_kimera(tmp_path)


class TestExport:
    def test_each_mission_round_trips_through_g2o(self, graphs: list) -> None:
        for graph in graphs:
            out = io.StringIO()
            written = write_g2o(graph, out)
            again = parse_g2o(io.StringIO(out.getvalue()), graph.name, graph.robot)
            own = [e for e in graph.edges if e.kind is not EdgeKind.INTER_ROBOT]
            assert written == len(own)
            assert again.vertices == graph.vertices
            # edges come back in their import order, with the g2o line as their origin
            assert [replace(e, origin=NO_ORIGIN) for e in again.edges] == [
                replace(e, origin=NO_ORIGIN) for e in own
            ]
