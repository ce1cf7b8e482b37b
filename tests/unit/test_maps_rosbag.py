"""Reading ROS bags as missions (`mapapi.maps.rosbag`): bags written by `rosbags`
itself, ROS 1 and ROS 2 in SQLite3 and MCAP, read back and compared with what
was written (`mapbench.bags`)."""

from __future__ import annotations

import math
import random
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mapapi.core.errors import UsageError
from mapapi.maps.cloud import PointCloud
from mapapi.maps.errors import MapImportError
from mapapi.maps.graph import EdgeKind, MissionGraph
from mapapi.maps.occupancy import OccupancyGrid
from mapapi.maps.rosbag import INFORMATION, MapSource, read_bag
from mapapi.maps.se3 import Pose, compose, inverse
from mapapi.maps.source import detect_format, read_source
from mapbench.bags import (
    GRID_ORIGIN,
    GRID_RESOLUTION,
    STORAGES,
    Messages,
    helix_pose,
    ring,
    room_cells,
    write_bag,
)
from tests.unit.grid_bags import write_grid_bag

pytest.importorskip("rosbags")

T0 = 1_700_000_000.0


def bag_at(tmp_path: Path, storage: str, **options: int | bool) -> Path:
    """A helix bag of `storage` in tmp_path."""
    name = "run.bag" if storage == "ros1" else "run"
    return write_bag(tmp_path / name, storage, **options)  # type: ignore[arg-type]


def by_name(sources: list[MapSource]) -> dict[str, MapSource]:
    return {s.name: s for s in sources}


class TestInverse:
    def test_compose_with_the_inverse_is_the_identity(self) -> None:
        rng = random.Random(7)
        for _ in range(200):
            q = [rng.gauss(0, 1) for _ in range(4)]
            n = math.sqrt(sum(v * v for v in q))
            pose = (rng.gauss(0, 5), rng.gauss(0, 5), rng.gauss(0, 5), *(v / n for v in q))
            for both in (compose(inverse(pose), pose), compose(pose, inverse(pose))):
                assert max(map(abs, both[:3])) < 1e-9
                assert abs(abs(both[6]) - 1) < 1e-12


@pytest.mark.parametrize("storage", STORAGES)
class TestEveryStorage:
    def test_odometry_becomes_a_timed_trajectory(self, tmp_path: Path, storage: str) -> None:
        path = bag_at(tmp_path, storage, poses=30)
        assert detect_format(path) == "rosbag"
        odom = by_name(read_source(path))["run-odom"]
        assert isinstance(odom, MissionGraph)
        assert odom.frame == "run-odom/odom"
        assert sorted(odom.vertices) == list(range(30))
        for i in range(30):
            assert odom.vertices[i] == pytest.approx(helix_pose(i), abs=1e-12)
            assert odom.timestamps[i] == pytest.approx(T0 + 0.1 * i, abs=1e-6)
        assert [e.kind for e in odom.edges] == [EdgeKind.ODOMETRY] * 29
        edge = odom.edges[4]
        assert (edge.source, edge.target) == (("run-odom", 4), ("run-odom", 5))
        assert compose(odom.vertices[4], edge.relative) == pytest.approx(odom.vertices[5])
        assert edge.information == INFORMATION

    def test_path_and_clouds(self, tmp_path: Path, storage: str) -> None:
        path = bag_at(tmp_path, storage, poses=25, cloud_every=10, cloud_points=16)
        found = by_name(read_bag(path))
        assert sorted(found) == ["run-odom", "run-path", "run-points"]
        track = found["run-path"]
        assert isinstance(track, MissionGraph)
        assert track.frame == "run-path/map"
        assert (len(track.vertices), len(track.edges)) == (25, 24)
        assert track.vertices[24] == pytest.approx(helix_pose(24))
        cloud = found["run-points"]
        assert isinstance(cloud, PointCloud)
        assert cloud.frame == "run-points/odom"
        want = np.concatenate([ring(helix_pose(i), 16) for i in (0, 10, 20)]).astype(np.float32)
        assert np.array_equal(cloud.points, want)


class TestChoices:
    def test_topics_choose_and_prefix_names(self, tmp_path: Path) -> None:
        path = bag_at(tmp_path, "mcap", poses=5)
        found = read_bag(path, ["/points"], mission="robot7-", robot="r7")
        assert [(s.name, s.robot) for s in found] == [("robot7-points", "r7")]

    def test_progress_counts_messages_to_the_total(self, tmp_path: Path) -> None:
        path = bag_at(tmp_path, "sqlite3", poses=2_500, cloud_every=0)
        seen: list[tuple[int, int]] = []
        read_bag(path, progress=lambda done, total: seen.append((done, total)))
        total = 1 + 2_500 + 1  # /tf_static, /odom, /path
        assert seen == [(1_000, total), (2_000, total), (total, total)]

    def test_tf_names_the_frame_when_the_header_has_none(self, tmp_path: Path) -> None:
        from rosbags.rosbag2 import StoragePlugin, Writer
        from rosbags.typesys import Stores, get_typestore

        store = get_typestore(Stores.ROS2_HUMBLE)
        build = Messages(store, ros1=False)
        with Writer(tmp_path / "tf", version=9, storage_plugin=StoragePlugin.MCAP) as writer:
            tf = writer.add_connection("/tf", "tf2_msgs/msg/TFMessage", typestore=store)
            odom = writer.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=store)
            writer.write(tf, 1, store.serialize_cdr(build.tf(1, "/world", "base_link"), tf.msgtype))
            for i in range(3):
                message = build.odometry(i + 2, helix_pose(i))
                message.header.frame_id = ""
                writer.write(odom, i + 2, store.serialize_cdr(message, odom.msgtype))
        (graph,) = read_bag(tmp_path / "tf")
        assert graph.frame == "tf-odom/world"

    def test_unknown_topics_and_types_are_refused(self, tmp_path: Path) -> None:
        path = bag_at(tmp_path, "sqlite3", poses=5)
        with pytest.raises(UsageError, match=r"no topic '/nope'; it has /odom, /path"):
            read_bag(path, ["/nope"])
        with pytest.raises(UsageError, match="tf2_msgs/msg/TFMessage, which is not imported"):
            read_bag(path, ["/tf_static"])
        with pytest.raises(UsageError, match="ROS bags only"):
            read_source(tmp_path / "run" / "metadata.yaml", "g2o", topics=["/odom"])


def tf_bag(
    path: Path,
    moves: list[tuple[int, Pose]],
    scans: list[tuple[int, str, np.ndarray]],
    mount: Pose | None = (0.5, 0.0, 0.3, 0.0, 0.0, 0.0, 1.0),
) -> Path:
    """An MCAP bag of odometry in `odom` and odom -> base_link on /tf at each of
    `moves` (ns, pose), base_link -> lidar at `mount` on /tf_static (none if None),
    and a PointCloud2 on /points per scan (ns, frame, points)."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    build = Messages(store, ros1=False)
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:

        def put(topic: str, msgtype: str, ns: int, message: object) -> None:
            if topic not in topics:
                topics[topic] = writer.add_connection(topic, msgtype, typestore=store)
            writer.write(topics[topic], ns, store.serialize_cdr(message, msgtype))

        topics: dict[str, object] = {}
        tf = "tf2_msgs/msg/TFMessage"
        if mount is not None:
            put("/tf_static", tf, 0, build.tf(0, "base_link", "lidar", mount))
        for ns, pose in moves:
            put("/tf", tf, ns, build.tf(ns, "odom", "base_link", pose))
            put("/odom", "nav_msgs/msg/Odometry", ns, build.odometry(ns, pose))
        for ns, frame, points in scans:
            put("/points", "sensor_msgs/msg/PointCloud2", ns, build.cloud(ns, points, frame))
    return path


def turned(x: float, degrees: float) -> Pose:
    """A pose at (x, 0, 0) turned `degrees` about z."""
    half = math.radians(degrees) / 2
    return (x, 0.0, 0.0, 0.0, 0.0, math.sin(half), math.cos(half))


class TestTfPlacesClouds:
    @pytest.mark.parametrize("storage", STORAGES)
    def test_a_lidar_frame_cloud_lands_on_the_odometry(self, tmp_path: Path, storage: str) -> None:
        path = bag_at(tmp_path, storage, poses=25, cloud_every=10, cloud_points=16, lidar=True)
        found = by_name(read_bag(path))
        cloud = found["run-points"]
        assert isinstance(cloud, PointCloud)
        assert (cloud.frame, found["run-odom"].frame) == ("run-points/odom", "run-odom/odom")
        want = np.concatenate([ring(helix_pose(i), 16) for i in (0, 10, 20)])
        assert np.abs(cloud.points - want).max() < 1e-4  # float32 in the lidar frame
        assert cloud.warnings == []

    def test_a_scan_between_two_transforms_is_interpolated(self, tmp_path: Path) -> None:
        moves = [(1_000_000_000, turned(0.0, 0.0)), (2_000_000_000, turned(2.0, 90.0))]
        points = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]], np.float32)
        path = tf_bag(tmp_path / "mid", moves, [(1_500_000_000, "lidar", points)])
        cloud = by_name(read_bag(path))["mid-points"]
        assert isinstance(cloud, PointCloud)
        # at t 1.5 s base_link is at x 1, turned 45 degrees; the lidar 0.5 m ahead, 0.3 up
        c = math.cos(math.radians(45))
        want = [[1 + 1.5 * c, 1.5 * c, 0.3], [1 + 0.5 * c, 0.5 * c, 1.3]]
        assert cloud.points == pytest.approx(np.array(want), abs=1e-6)
        assert cloud.frame == "mid-points/odom"

    def test_tf_frame_chooses_where_the_clouds_go(self, tmp_path: Path) -> None:
        moves = [(1_000_000_000, turned(0.0, 0.0)), (2_000_000_000, turned(2.0, 90.0))]
        points = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]], np.float32)
        path = tf_bag(tmp_path / "mid", moves, [(1_500_000_000, "lidar", points)])
        found = by_name(read_bag(path, tf_frame="base_link"))
        cloud = found["mid-points"]
        assert isinstance(cloud, PointCloud)
        # only the lidar's mount (0.5 m ahead, 0.3 m up) lies between the two frames
        assert cloud.points == pytest.approx(np.array([[1.5, 0, 0.3], [0.5, 0, 1.3]]), abs=1e-6)
        assert cloud.frame == "mid-points/base_link"
        assert found["mid-odom"].frame == "mid-odom/odom"  # the trajectory keeps its own
        as_given = by_name(read_bag(path, tf_frame="lidar"))["mid-points"]
        assert isinstance(as_given, PointCloud)
        assert as_given.points == pytest.approx(points)
        assert as_given.warnings == []

    def test_a_tf_frame_no_transform_names_is_refused(self, tmp_path: Path) -> None:
        moves = [(1_000_000_000, turned(0.0, 0.0))]
        points = np.array([[1.0, 0.0, 0.0]], np.float32)
        path = tf_bag(tmp_path / "mid", moves, [(1_000_000_000, "lidar", points)])
        with pytest.raises(UsageError, match=r"--tf-frame map: .*frames: base_link, lidar, odom"):
            read_bag(path, tf_frame="map")

    def test_without_a_tf_path_the_points_stay_and_a_warning_says_so(self, tmp_path: Path) -> None:
        points = np.array([[1.0, 2.0, 3.0]], np.float32)
        moves = [(1, turned(0.0, 0.0)), (2, turned(1.0, 0.0))]
        path = tf_bag(tmp_path / "lost", moves, [(1, "camera", points)], mount=None)
        cloud = by_name(read_bag(path))["lost-points"]
        assert isinstance(cloud, PointCloud)
        assert cloud.frame == "lost-points/camera"
        assert np.array_equal(cloud.points, points)
        assert cloud.warnings == [
            "topic /points: no TF path from camera to odom: camera is in the tree of camera, "
            "odom in that of odom; its points stay in camera, as its messages give them"
        ]

    def test_a_cloud_that_names_no_frame_stays_and_says_so(self, tmp_path: Path) -> None:
        points = np.array([[1.0, 2.0, 3.0]], np.float32)
        path = tf_bag(tmp_path / "bare", [(1, turned(0.0, 0.0))], [(1, "", points)])
        cloud = by_name(read_bag(path))["bare-points"]
        assert isinstance(cloud, PointCloud)
        assert (cloud.frame, cloud.warnings) == (
            "bare-points/map",
            [
                "topic /points: a message names no frame; its points stay in no frame, "
                "as its messages give them"
            ],
        )
        assert np.array_equal(cloud.points, points)

    def test_scans_stamped_outside_the_tf_are_left_out_and_counted(self, tmp_path: Path) -> None:
        moves = [(10**9 * k, turned(float(k), 0.0)) for k in (1, 2)]
        ring_points = ring(helix_pose(0), 4).astype(np.float32)
        scans = [(10**9 * k // 2, "lidar", ring_points) for k in (1, 3, 5)]  # 0.5, 1.5, 2.5 s
        cloud = by_name(read_bag(tf_bag(tmp_path / "late", moves, scans)))["late-points"]
        assert isinstance(cloud, PointCloud)
        assert len(cloud.points) == 4  # the scan at 1.5 s
        (warning,) = cloud.warnings
        assert warning.startswith(
            "topic /points: 2 of 3 scans left out, TF cannot place them in odom at their "
            "time (TF odom -> base_link is known from 1.000 to 2.000 s, not at 0.500 s"
        )


@pytest.mark.parametrize("storage", STORAGES)
def test_the_last_occupancy_grid_becomes_a_grid_mission(tmp_path: Path, storage: str) -> None:
    path = bag_at(tmp_path, storage, poses=5, grid=True)
    grid = by_name(read_bag(path))["run-map"]
    assert isinstance(grid, OccupancyGrid)
    assert grid.frame == "run-map/map"
    assert np.array_equal(grid.cells, room_cells())  # the second message, not the unknown first
    assert (grid.x0, grid.y0, grid.z) == GRID_ORIGIN[:3]
    assert grid.resolution == GRID_RESOLUTION  # 0.05, not its float32 0.0500000007
    assert grid.stamp == pytest.approx(T0 + 0.4, abs=1e-6)
    assert [s.name for s in read_bag(path, ["/map"])] == ["run-map"]


def test_a_turned_grid_keeps_its_yaw_and_a_tilted_one_is_refused(tmp_path: Path) -> None:
    turned = (1.0, 2.0, 0.0, 0.0, 0.0, math.sin(0.25), math.cos(0.25))  # 0.5 rad of yaw
    write_grid_bag(tmp_path / "turned", room_cells(4, 3), turned, "/floor/map")
    (grid,) = read_bag(tmp_path / "turned")
    assert isinstance(grid, OccupancyGrid)
    assert (grid.x0, grid.y0, grid.yaw) == (1.0, 2.0, pytest.approx(0.5, abs=1e-12))
    tilted = (1.0, 2.0, 0.0, math.sin(0.1), 0.0, 0.0, math.cos(0.1))
    write_grid_bag(tmp_path / "tilted", room_cells(4, 3), tilted, "/floor/map")
    with pytest.raises(MapImportError, match=r"topic /floor/map, message 0 .* tilted"):
        read_bag(tmp_path / "tilted")


class TestErrors:
    def test_a_corrupt_bag_is_a_clean_error(self, tmp_path: Path) -> None:
        path = bag_at(tmp_path, "ros1", poses=50)
        data = path.read_bytes()
        path.write_bytes(data[: len(data) // 2])
        with pytest.raises(MapImportError, match=r"run\.bag"):
            read_bag(path)
        (tmp_path / "junk.bag").write_bytes(b"not a bag at all")
        with pytest.raises(MapImportError, match="not a ROS bag rosbags can read"):
            read_bag(tmp_path / "junk.bag")

    def test_a_bad_message_names_its_topic_and_index(self, tmp_path: Path) -> None:
        from rosbags.rosbag2 import StoragePlugin, Writer
        from rosbags.typesys import Stores, get_typestore

        store = get_typestore(Stores.ROS2_HUMBLE)
        build = Messages(store, ros1=False)
        with Writer(tmp_path / "bad", version=9, storage_plugin=StoragePlugin.SQLITE3) as writer:
            odom = writer.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=store)
            for i in range(5):
                pose = helix_pose(i) if i != 3 else (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
                raw = store.serialize_cdr(build.odometry(i + 1, pose), odom.msgtype)
                writer.write(odom, i + 1, raw)
        with pytest.raises(MapImportError, match=r"topic /odom, message 3 .*quaternion is zero"):
            read_bag(tmp_path / "bad")

    def test_a_cloud_without_z_names_its_message(self, tmp_path: Path) -> None:
        from rosbags.rosbag1 import Writer
        from rosbags.typesys import Stores, get_typestore

        store = get_typestore(Stores.ROS1_NOETIC)
        message = Messages(store, ros1=True).cloud(5, np.zeros((3, 3)))
        message.fields[2].name = "intensity"
        with Writer(tmp_path / "c.bag") as writer:
            points = writer.add_connection("/points", message.__msgtype__, typestore=store)
            writer.write(points, 5, store.serialize_ros1(message, points.msgtype))
        with pytest.raises(MapImportError, match=r"/points, message 0 .* no field 'z'"):
            read_bag(tmp_path / "c.bag")

    def test_other_imports_do_not_load_rosbags(self) -> None:
        code = (
            "import sys; from mapapi.maps.source import read_source; "
            "read_source('sample_maps/pose_graphs/intel.g2o'); "
            "print('rosbags' in sys.modules)"
        )
        root = Path(__file__).resolve().parents[2]
        ran = subprocess.run(
            [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=root
        )
        assert ran.stdout.strip() == "False"
