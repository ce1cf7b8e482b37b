"""TUM and KITTI trajectory export (mapapi.maps.trajectory, jobs.export_format):
real missions imported into a peer, written out, and read back with evo, the
evaluation tool these files are for."""

from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np
import pytest
from evo.tools.file_interface import read_kitti_poses_file, read_tum_trajectory_file

from mapapi.app import memory_peer
from mapapi.core.errors import UsageError
from mapapi.maps import MissionGraph, import_missions, load_graph
from mapapi.maps.jobs import EXPORT_FORMATS, export_format
from mapapi.maps.operations import MapOperations
from mapapi.maps.se3 import from_se2, yaw
from mapapi.maps.source import read_source
from mapapi.maps.trajectory import rotation_matrix, trajectory_of, write_kitti, write_tum
from mapctl.commands.maps import EXPORT_FORMATS as CLI_EXPORT_FORMATS

SAMPLES = Path(__file__).resolve().parents[2] / "sample_maps"
INTEL = SAMPLES / "pose_graphs" / "intel.g2o"
ROBOT0 = SAMPLES / "kimera_multi_tunnels_8robots" / "robot0" / "measurements.csv"
ROOM = SAMPLES / "point_clouds" / "room_scan1.pcd"


@pytest.fixture
def ops() -> MapOperations:
    return MapOperations(memory_peer())


async def _stored(ops: MapOperations, path: Path, mission: str) -> MissionGraph:
    """The one mission of `path` imported (named `mission`, a prefix for a Kimera
    file), read back from the store."""
    (source,) = read_source(path, mission=mission)
    await import_missions(ops.peer, [source])
    return await load_graph(ops.peer, source.name)


def _positions(graph: MissionGraph) -> np.ndarray:
    return np.array([graph.vertices[i][:3] for i in sorted(graph.vertices)])


def _quaternions_wxyz(graph: MissionGraph) -> np.ndarray:
    return np.array([np.roll(graph.vertices[i][3:], 1) for i in sorted(graph.vertices)])


class TestEvoReadsWhatWeWrite:
    async def test_a_3d_kimera_mission_as_tum(self, ops: MapOperations, tmp_path: Path) -> None:
        stored = await _stored(ops, ROBOT0, "tunnels-")  # a prefix: "tunnels-robot0"
        out = tmp_path / "robot0.tum"

        info = await ops.export_map(stored.name, str(out))

        assert info == {
            "frame": "mission",
            "mission": stored.name,
            "path": str(out),
            "format": "tum",
            "poses": 105,
            "time": "index",  # a Kimera CSV holds no time
        }
        read = read_tum_trajectory_file(out)
        assert read.num_poses == 105
        assert np.array_equal(read.timestamps, np.arange(105, dtype=float))
        assert np.array_equal(read.positions_xyz, _positions(stored))  # bit for bit
        assert np.array_equal(read.orientations_quat_wxyz, _quaternions_wxyz(stored))

    async def test_a_3d_kimera_mission_as_kitti(self, ops: MapOperations, tmp_path: Path) -> None:
        stored = await _stored(ops, ROBOT0, "tunnels-")
        out = tmp_path / "robot0.kitti"

        info = await ops.export_map(stored.name, str(out))

        assert (info["format"], info["poses"]) == ("kitti", 105)
        read = read_kitti_poses_file(out)
        assert read.num_poses == 105
        for matrix, index in zip(read.poses_se3, sorted(stored.vertices), strict=True):
            pose = stored.vertices[index]
            assert matrix[:3, 3].tolist() == list(pose[:3])
            assert np.allclose(matrix[:3, :3], rotation_matrix(pose), atol=0, rtol=0)
            assert np.allclose(matrix[:3, :3] @ matrix[:3, :3].T, np.eye(3), atol=1e-9)

    async def test_a_2d_graph_becomes_3d_with_z_0_and_a_yaw_quaternion(
        self, ops: MapOperations, tmp_path: Path
    ) -> None:
        stored = await _stored(ops, INTEL, "intel")
        tum, kitti = tmp_path / "intel.txt", tmp_path / "intel-kitti.txt"

        await ops.export_map("intel", str(tum), fmt="tum")
        await ops.export_map("intel", str(kitti), fmt="kitti")

        read = read_tum_trajectory_file(tum)
        assert read.num_poses == 1_728
        assert not read.positions_xyz[:, 2].any()
        assert not read.orientations_quat_wxyz[:, 1:3].any()  # qx = qy = 0: yaw only
        assert np.array_equal(read.positions_xyz, _positions(stored))
        matrices = read_kitti_poses_file(kitti).poses_se3
        for matrix, index in zip(matrices, sorted(stored.vertices), strict=True):
            theta = yaw(stored.vertices[index])
            assert math.atan2(matrix[1, 0], matrix[0, 0]) == pytest.approx(theta, abs=1e-12)
            assert matrix[2].tolist()[:3] == [0.0, 0.0, 1.0]

    async def test_vertex_timestamps_are_the_tum_times(
        self, ops: MapOperations, tmp_path: Path
    ) -> None:
        graph = MissionGraph("timed", planar=True)
        graph.vertices = {i: from_se2(0.1 * i, 0.0, 0.01 * i) for i in range(5)}
        graph.timestamps = {i: 976052857.337284 + 0.2 * i for i in range(5)}
        await import_missions(ops.peer, [graph])
        out = tmp_path / "timed.tum"

        info = await ops.export_map("timed", str(out))

        assert info["time"] == "timestamp"
        assert (await load_graph(ops.peer, "timed")).timestamps == graph.timestamps
        read = read_tum_trajectory_file(out)
        assert read.timestamps.tolist() == [graph.timestamps[i] for i in range(5)]


class TestFormats:
    @pytest.mark.parametrize(
        ("name", "fmt"),
        [
            ("a.tum", "tum"),
            ("a.KITTI", "kitti"),
            ("a.g2o", "g2o"),
            ("a.ply", "ply"),
            ("a.yaml", "grid"),  # nav2's map YAML, its PGM beside it
            ("a.YML", "grid"),
        ],
    )
    def test_the_extension_names_the_format(self, name: str, fmt: str) -> None:
        assert export_format(Path(name)) == fmt

    def test_txt_is_ambiguous_and_asks_for_format(self) -> None:
        with pytest.raises(UsageError, match="--format tum or --format kitti"):
            export_format(Path("poses.txt"))
        assert export_format(Path("poses.txt"), "kitti") == "kitti"

    def test_an_unknown_extension_or_format_is_refused(self) -> None:
        with pytest.raises(UsageError, match="pass --format"):
            export_format(Path("poses.csv"))
        with pytest.raises(UsageError, match="unknown format 'png'"):
            export_format(Path("poses.png"), "png")
        with pytest.raises(UsageError, match="pass --format"):
            export_format(Path("poses.bag"))  # a ROS 1 bag's name: we write ROS 2 folders
        with pytest.raises(UsageError, match=r"must end in \.ply"):
            export_format(Path("cloud.txt"), "ply")

    def test_the_cli_offers_the_library_formats(self) -> None:
        assert CLI_EXPORT_FORMATS == EXPORT_FORMATS

    async def test_a_cloud_has_no_trajectory(self, ops: MapOperations, tmp_path: Path) -> None:
        await import_missions(ops.peer, read_source(ROOM, mission="room"))
        with pytest.raises(UsageError, match=r"'room' has no pose graph.*export it as \.ply"):
            await ops.export_map("room", str(tmp_path / "room.tum"))
        assert not (tmp_path / "room.tum").exists()


def test_an_untimed_vertex_among_timed_ones_makes_the_index_the_time() -> None:
    graph = MissionGraph("mixed")
    graph.vertices = {i: from_se2(i, 0, 0) for i in range(3)}
    graph.timestamps = {0: 10.0, 2: 12.0}
    trajectory = trajectory_of(graph)
    assert (trajectory.timed, trajectory.stamps) == (False, [0.0, 1.0, 2.0])
    out = io.StringIO()
    assert write_tum(trajectory, out) == 3
    assert write_kitti(trajectory, io.StringIO()) == 3
    assert out.getvalue().splitlines()[1] == "1.0 1.0 0.0 0.0 0.0 0.0 0.0 1.0"
