"""Landmark SLAM (issue 17 §3): g2o `VERTEX_XY` / `EDGE_SE2_XY` and GTSAM's
ODOMETRY/LANDMARK text (Victoria Park) fill the `landmarks` table, their
observations are `LANDMARK` edges, and missions, export, plot and the spatial
index see them. Stores are real SQLite repositories (`make_peer`)."""

from __future__ import annotations

import io
import math
from pathlib import Path

import pytest

from mapapi import Peer
from mapapi.lookup.spatial import BBox
from mapapi.maps.errors import MapImportError
from mapapi.maps.g2o import parse_g2o, write_g2o
from mapapi.maps.graph import EdgeKind
from mapapi.maps.gtsam_text import parse_gtsam_landmarks
from mapapi.maps.operations import MapOperations
from mapapi.maps.se3 import compose, upper_index
from mapapi.maps.source import detect_format
from mapapi.maps.text_file import read_text

SAMPLES = Path(__file__).resolve().parents[2] / "sample_maps"
VICTORIA = SAMPLES / "landmarks" / "victoria_park.txt"

SMALL = (
    "VERTEX_SE2 0 0 0 0\n"
    "VERTEX_SE2 1 1.50 0 0.1\n"
    "VERTEX_XY 7 2.5 -1.25\n"
    "EDGE_SE2 0 1 1.5 0 0.1 100 0 0 100 0 1000\n"
    "EDGE_SE2_XY 0 7 2.5 -1.25 4 0.5 9\n"
    "EDGE_SE2_XY 1 7 1.0e0 -1.25 4 0 4\n"
)


@pytest.fixture
async def ops(make_peer) -> MapOperations:  # type: ignore[no-untyped-def]
    peer: Peer = await make_peer()
    return MapOperations(peer)


class TestG2oLandmarks:
    def test_landmarks_and_their_observations_are_read(self) -> None:
        graph = parse_g2o(io.StringIO(SMALL), "m")

        assert graph.landmarks == {7: (2.5, -1.25, 0.0)}
        assert sorted(graph.vertices) == [0, 1]
        seen = [e for e in graph.edges if e.kind is EdgeKind.LANDMARK]
        assert [(e.source, e.target) for e in seen] == [(("m", 0), ("m", 7)), (("m", 1), ("m", 7))]
        info = seen[0].information
        assert (info[upper_index(0, 0)], info[upper_index(0, 1)], info[upper_index(1, 1)]) == (
            4,
            0.5,
            9,
        )
        assert sum(1 for v in info if v) == 3
        assert graph.elements() == 2 + 1 + 3

    def test_a_landmark_without_a_vertex_starts_at_its_first_observation(self) -> None:
        text = "VERTEX_SE2 0 1 2 1.5707963267948966\nEDGE_SE2_XY 0 3 2 0 1 0 1\n"
        graph = parse_g2o(io.StringIO(text), "m")
        x, y, z = graph.landmarks[3]
        assert (round(x, 12), round(y, 12), z) == (1.0, 4.0, 0.0)  # 2 m ahead, facing +y

    @pytest.mark.parametrize(
        "bad",
        ["EDGE_SE2_XY 0 1 1 1 1 0 1", "EDGE_SE2 0 7 1 0 0 1 0 0 1 0 1", "EDGE_SE2_XY 0 7 1 1 1 0"],
    )
    def test_a_landmark_taken_for_a_pose_is_refused_naming_the_line(self, bad: str) -> None:
        with pytest.raises(MapImportError, match=r"bad\.g2o:7: ") as caught:
            parse_g2o(io.StringIO(f"{SMALL}{bad}\n"), "m", source="bad.g2o")
        assert caught.value.line == 7

    def test_export_writes_the_file_back(self) -> None:
        out = io.StringIO()
        assert write_g2o(parse_g2o(io.StringIO(SMALL), "m"), out) == 3
        assert out.getvalue() == SMALL

    async def test_a_landmark_map_round_trips_through_a_repository(
        self, ops: MapOperations, tmp_path: Path
    ) -> None:
        source = tmp_path / "small.g2o"
        source.write_text(SMALL)
        info = await ops.imports.import_map(str(source))
        assert info["missions"][0]["landmarks"] == 1
        assert info["elements"] == 6

        await ops.export_map("small", str(tmp_path / "out.g2o"))
        assert (tmp_path / "out.g2o").read_text() == SMALL


class TestVictoriaPark:
    def test_the_file_is_recognised_by_its_first_record(self) -> None:
        assert detect_format(VICTORIA) == "gtsam-landmarks"

    def test_counts_match_the_dataset_readme(self) -> None:
        graph = read_text(parse_gtsam_landmarks, VICTORIA)
        kinds = [e.kind for e in graph.edges]
        assert len(graph.vertices) == 6_969
        assert (kinds.count(EdgeKind.ODOMETRY), kinds.count(EdgeKind.LANDMARK)) == (6_968, 3_640)
        assert len(graph.landmarks) == 151
        box = graph.bbox()
        assert box is not None
        assert 380 < box.xmax - box.xmin < 420
        assert 270 < box.ymax - box.ymin < 310

    def test_a_landmark_starts_where_its_first_observation_puts_it(self) -> None:
        graph = read_text(parse_gtsam_landmarks, VICTORIA)
        # line 5: LANDMARK 4 5 11.5387 -3.2007 0.4 0 0.4
        first = next(e for e in graph.edges if e.target == ("victoria_park", 5))
        assert first.origin.line == 5
        where = compose(graph.vertices[4], (11.5387, -3.2007, 0.0, 0.0, 0.0, 0.0, 1.0))
        assert graph.landmarks[5] == where[:3]
        # covariance diag(0.4, 0.4) is information diag(2.5, 2.5)
        assert math.isclose(first.information[upper_index(0, 0)], 2.5)

    @pytest.mark.parametrize(
        ("bad", "match"),
        [
            ("LANDMARK 4 5 1 1 0.4 0", "needs 7 values, found 6"),
            ("LANDMARK 4 5 1 1 0.4 1 0.4", "not positive definite"),
            ("ODOMETRY 4 -6 0 0 0 1 0 0 1 0 1", "natural"),
            ("BR 4 5 0.1 3 0.1 0.1", "unsupported record 'BR'"),
        ],
    )
    def test_a_bad_line_is_named(self, bad: str, match: str) -> None:
        text = f"ODOMETRY 0 1 1 0 0 1 0 0 1 0 1\n\n{bad}\n"
        with pytest.raises(MapImportError, match=match) as caught:
            parse_gtsam_landmarks(io.StringIO(text), "m", source="vp.txt")
        assert str(caught.value).startswith("vp.txt:3: ")

    async def test_missions_and_the_spatial_index_see_the_landmarks(
        self, ops: MapOperations
    ) -> None:
        await ops.imports.import_map(str(VICTORIA), mission="vp")
        (mission,) = (await ops.missions())["missions"]
        assert (mission["vertices"], mission["edges"], mission["landmarks"]) == (6969, 10608, 151)
        graph = read_text(parse_gtsam_landmarks, VICTORIA)
        box = graph.bbox()
        assert box is not None
        assert mission["bbox"] == list(box.as_tuple())

        landmarks = mission["chunks"]["landmarks"]
        x, y, _ = graph.landmarks[5]
        near = BBox(x - 0.5, y - 0.5, -1, x + 0.5, y + 0.5, 1)
        found = await ops.peer.query_bbox(near, "landmarks")
        assert [f.ref.chunk for f in found] == [landmarks]

    async def test_plot_draws_the_landmarks(self, ops: MapOperations, tmp_path: Path) -> None:
        await ops.imports.import_map(str(VICTORIA), mission="vp")
        drawn = await ops.plot_map(str(tmp_path / "vp.png"))
        assert drawn["missions"] == ["vp"]
        assert (tmp_path / "vp.png").stat().st_size > 10_000
