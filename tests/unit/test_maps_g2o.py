"""g2o reading and writing (mapapi.maps.g2o), on the shipped sample maps."""

import io
import math
from dataclasses import replace
from pathlib import Path

import pytest

from mapapi.maps import EdgeKind, MapImportError, MissionGraph, parse_g2o, read_g2o, write_g2o
from mapapi.maps.graph import NO_ORIGIN
from mapapi.maps.se3 import IDENTITY, compose, lift_information, upper_index

SAMPLES = Path(__file__).resolve().parents[2] / "sample_maps" / "pose_graphs"
INTEL = SAMPLES / "intel.g2o"
GARAGE = SAMPLES / "parking-garage.g2o"


def reparse(graph: MissionGraph, planar: bool | None = None) -> MissionGraph:
    out = io.StringIO()
    write_g2o(graph, out, planar=planar)
    return parse_g2o(io.StringIO(out.getvalue()), graph.name, graph.robot)


class TestSampleCounts:
    def test_intel_matches_the_datasets_readme(self) -> None:
        graph = read_g2o(INTEL)
        assert (graph.name, graph.planar) == ("intel", True)
        assert len(graph.vertices) == 1_728
        assert len(graph.edges) == 2_512
        assert graph.count(EdgeKind.ODOMETRY) == 1_727
        assert graph.count(EdgeKind.LOOP) == 785

    def test_parking_garage_matches_the_datasets_readme(self) -> None:
        graph = read_g2o(GARAGE, mission="garage", robot="r1")
        assert (graph.name, graph.robot, graph.planar) == ("garage", "r1", False)
        assert len(graph.vertices) == 1_661
        assert len(graph.edges) == 6_275
        assert graph.count(EdgeKind.ODOMETRY) == 1_660

    def test_intel_box_is_about_25_by_26_m_and_flat(self) -> None:
        box = read_g2o(INTEL).bbox()
        assert box is not None
        assert 20 < box.xmax - box.xmin < 30
        assert 20 < box.ymax - box.ymin < 30
        assert box.zmin == box.zmax == 0.0


class TestLifting:
    def test_se2_yaw_becomes_a_z_rotation_and_information_moves_to_x_y_rz(self) -> None:
        text = "VERTEX_SE2 0 1 2 0\nVERTEX_SE2 1 1 2 1.5\nEDGE_SE2 0 1 0 0 1.5 1 2 3 4 5 6\n"
        graph = parse_g2o(io.StringIO(text), "m")
        pose = graph.vertices[1]
        assert pose[:3] == (1.0, 2.0, 0.0)
        assert pose[5] == pytest.approx(math.sin(0.75))
        assert pose[6] == pytest.approx(math.cos(0.75))
        info = graph.edges[0].information
        assert len(info) == 21
        assert info[upper_index(0, 0)] == 1
        assert info[upper_index(0, 1)] == 2
        assert info[upper_index(0, 5)] == 3
        assert info[upper_index(1, 1)] == 4
        assert info[upper_index(1, 5)] == 5
        assert info[upper_index(5, 5)] == 6
        assert sum(info) == 21
        assert lift_information((1, 2, 3, 4, 5, 6)) == info

    def test_edges_only_graph_chains_odometry_from_the_identity(self) -> None:
        text = "EDGE_SE2 0 1 1 0 1.5707963267948966 1 0 0 1 0 1\n"
        text += "EDGE_SE2 1 2 1 0 0 1 0 0 1 0 1\nEDGE_SE2 2 0 0 0 0 1 0 0 1 0 1\n"
        graph = parse_g2o(io.StringIO(text), "m")
        assert graph.vertices[0] == IDENTITY
        assert graph.vertices[1][:2] == (1.0, 0.0)
        assert graph.vertices[2][0] == pytest.approx(1.0)
        assert graph.vertices[2][1] == pytest.approx(1.0)
        assert [e.kind for e in graph.edges] == [
            EdgeKind.ODOMETRY,
            EdgeKind.ODOMETRY,
            EdgeKind.LOOP,
        ]

    def test_chained_garage_trajectory_follows_the_given_vertices(self) -> None:
        given = read_g2o(GARAGE)
        edges_only = "".join(
            line for line in GARAGE.read_text().splitlines(keepends=True) if line.startswith("EDGE")
        )
        chained = parse_g2o(io.StringIO(edges_only), "garage")
        assert chained.vertices.keys() == given.vertices.keys()
        # the file's vertices are the odometry chain: they agree up to rounding
        for index in (1, 100, 1660):
            a, b = chained.vertices[index], given.vertices[index]
            assert math.dist(a[:3], b[:3]) < 1e-3 * (1 + math.dist(b[:3], IDENTITY[:3]))

    def test_compose_with_identity_is_a_no_op(self) -> None:
        pose = (1.0, 2.0, 3.0, 0.0, 0.0, math.sin(0.3), math.cos(0.3))
        assert compose(IDENTITY, pose) == pytest.approx(pose)
        assert compose(pose, IDENTITY) == pytest.approx(pose)


class TestMalformedInput:
    @pytest.mark.parametrize(
        ("bad", "match"),
        [
            ("VERTEX_SE2 2 0 0", "needs 4 values, found 3"),
            ("VERTEX_SE2 2 0 zero 0", "could not convert"),
            ("VERTEX_SE2 2 0 nan 0", "finite"),
            ("VERTEX_SE2 1.5 0 0 0", "not a natural number"),
            ("VERTEX_SE2 0 5 5 5", "defined twice"),
            ("VERTEX_XY 2 0", "needs 3 values, found 2"),
            ("VERTEX_XY 0 1 1", "defined twice"),
            ("VERTEX_SE2_XY 2 0 0", "unsupported record .VERTEX_SE2_XY."),
            ("VERTEX_SE3:QUAT 2 0 0 0 0 0 0 1", "2D and 3D"),
            ("EDGE_SE2 0 1 1 0 0 1 0 0 1 0", "needs 11 values"),
        ],
    )
    def test_the_error_names_the_line(self, bad: str, match: str) -> None:
        text = f"# a comment\nVERTEX_SE2 0 0 0 0\n\n{bad}\nVERTEX_SE2 9 0 0 0\n"
        with pytest.raises(MapImportError, match=match) as caught:
            parse_g2o(io.StringIO(text), "m", source="bad.g2o")
        assert caught.value.line == 4
        assert str(caught.value).startswith("bad.g2o:4: ")

    def test_a_quaternion_that_is_not_unit_is_refused(self) -> None:
        text = "VERTEX_SE3:QUAT 0 0 0 0 0 0 0 2\n"
        with pytest.raises(MapImportError, match="quaternion norm"):
            parse_g2o(io.StringIO(text), "m")

    def test_fix_lines_are_ignored(self) -> None:
        graph = parse_g2o(io.StringIO("VERTEX_SE2 0 0 0 0\nFIX 0\n"), "m")
        assert list(graph.vertices) == [0]

    def test_a_malformed_sample_names_its_line(self, tmp_path: Path) -> None:
        lines = INTEL.read_text().splitlines(keepends=True)
        lines[2000] = "EDGE_SE2 1 2 oops\n"
        broken = tmp_path / "broken.g2o"
        broken.write_text("".join(lines))
        with pytest.raises(MapImportError, match=r"broken\.g2o:2001: EDGE_SE2 needs 11"):
            read_g2o(broken)


class TestRoundTrip:
    def test_3d_graph_reads_back_identically(self) -> None:
        graph = read_g2o(GARAGE)
        again = reparse(graph)
        assert again.vertices == graph.vertices
        assert again.edges == graph.edges

    def test_2d_graph_exported_as_3d_reads_back_identically(self) -> None:
        graph = read_g2o(INTEL)
        again = reparse(graph, planar=False)
        assert again.vertices == graph.vertices
        assert [replace(e, origin=NO_ORIGIN) for e in again.edges] == [
            replace(e, origin=NO_ORIGIN) for e in graph.edges
        ]

    def test_2d_graph_exported_as_2d_reads_back_equal_up_to_rounding(self) -> None:
        graph = read_g2o(INTEL)
        again = reparse(graph)
        assert again.planar
        assert again.vertices.keys() == graph.vertices.keys()
        for index, pose in graph.vertices.items():
            assert again.vertices[index] == pytest.approx(pose, abs=1e-12)
        assert [(e.source, e.target, e.kind) for e in again.edges] == [
            (e.source, e.target, e.kind) for e in graph.edges
        ]
        for ours, theirs in zip(again.edges, graph.edges, strict=True):
            assert ours.relative == pytest.approx(theirs.relative, abs=1e-12)
            assert ours.information == theirs.information

    def test_a_3d_graph_cannot_be_written_as_2d(self) -> None:
        with pytest.raises(ValueError, match="not planar"):
            write_g2o(read_g2o(GARAGE), io.StringIO(), planar=True)
