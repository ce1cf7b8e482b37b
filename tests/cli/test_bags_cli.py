"""`mapctl import` of ROS bags and `mapctl export --format bag` (issue 17 §3, §4):
bags written by `rosbags` imported into a real repository, and exported bags
read back with `rosbags` and compared with the stored poses and points."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from mapbench.bags import GRID_ORIGIN, STORAGES, room_cells, write_bag
from tests.cli.conftest import Mapctl
from tests.unit.test_maps_rosbag import tf_bag

pytest.importorskip("rosbags")

SAMPLES = Path(__file__).resolve().parents[2] / "sample_maps"
LOG = SAMPLES / "laser_logs" / "intel-head.clf.bz2"
TUNNELS = SAMPLES / "kimera_multi_tunnels_8robots"
EXIT_USAGE = 2


def read_back(folder: Path) -> dict[str, list[tuple[int, Any]]]:
    """topic -> (record time in ns, message) of every message of a bag, read by rosbags."""
    from rosbags.highlevel import AnyReader

    found: dict[str, list[tuple[int, Any]]] = {}
    with AnyReader([folder]) as reader:
        for connection, ns, raw in reader.messages():
            message = reader.deserialize(raw, connection.msgtype)
            found.setdefault(connection.topic, []).append((ns, message))
    return found


def tum_rows(mapctl: Mapctl, mission: str, tmp_path: Path, *options: str) -> list[list[float]]:
    """The stored poses of `mission`, as its TUM export gives them (bit for bit)."""
    target = tmp_path / f"{mission}.tum"
    mapctl("export", mission, "-o", str(target), *options)
    return [[float(v) for v in line.split()] for line in target.read_text().splitlines()]


class TestImport:
    @pytest.mark.parametrize("storage", STORAGES)
    def test_every_storage_imports_into_a_repository(
        self, mapctl: Mapctl, tmp_path: Path, storage: str
    ) -> None:
        bag = write_bag(tmp_path / ("run.bag" if storage == "ros1" else "run"), storage, poses=40)
        info = mapctl.json("import", str(bag), "--robot", "r1")
        assert info["format"] == "rosbag"
        counts = {
            m["name"]: (m["robot"], m["vertices"], m["edges"], m["points"])
            for m in info["missions"]
        }
        assert counts == {
            "run-odom": ("r1", 40, 39, 0),
            "run-path": ("r1", 40, 39, 0),
            "run-points": ("r1", 0, 0, 4 * 64),
        }
        assert info["elements"] == 2 * (40 + 39)
        listed = {m["name"]: m["kind"] for m in mapctl.json("missions")["missions"]}
        assert listed == {"run-odom": "graph", "run-path": "graph", "run-points": "cloud"}
        rows = tum_rows(mapctl, "run-odom", tmp_path)
        assert rows[3][0] == pytest.approx(1_700_000_000.3, abs=1e-6)  # the header's stamp

    def test_topics_choose_separated_by_commas_or_repeated(
        self, mapctl: Mapctl, tmp_path: Path
    ) -> None:
        bag = write_bag(tmp_path / "run.bag", "ros1", poses=5)
        one = mapctl.json("import", str(bag), "--topics", "/odom,/points", "--mission", "a-")
        assert [m["name"] for m in one["missions"]] == ["a-odom", "a-points"]
        two = mapctl.json(
            "import", str(bag), "--topics", "/path", "--topics", "/odom", "--mission", "b-"
        )
        assert sorted(m["name"] for m in two["missions"]) == ["b-odom", "b-path"]

    def test_bad_bags_and_topics_exit_2_and_commit_nothing(
        self, mapctl: Mapctl, tmp_path: Path
    ) -> None:
        junk = tmp_path / "junk.bag"
        junk.write_bytes(b"#ROSBAG V2.0\n" + bytes(100))
        outcome = mapctl.main("import", str(junk))
        assert outcome.code == EXIT_USAGE
        assert outcome.err_lines[0].startswith(f"error: {junk}: not a ROS bag rosbags can read")
        asked = mapctl.main("import", str(tmp_path / "junk.bag"), "--topics", "/map")
        assert asked.code == EXIT_USAGE
        assert mapctl.json("log") == []


class TestTf:
    def test_a_lidar_cloud_is_placed_where_the_odometry_cloud_is(
        self, mapctl: Mapctl, tmp_path: Path
    ) -> None:
        sensor = write_bag(tmp_path / "sensor", "mcap", poses=40, lidar=True)
        plain = write_bag(tmp_path / "plain", "mcap", poses=40)
        boxes = {}
        for bag in (sensor, plain):
            info = mapctl.json("import", str(bag), "--topics", "/odom,/points")
            clouds = [m for m in info["missions"] if m["points"]]
            assert [m["warnings"] for m in info["missions"]] == [[], []]
            boxes[bag.name] = clouds[0]["bbox"]
        assert boxes["sensor"] == pytest.approx(boxes["plain"], abs=1e-4)

    def test_tf_frame_places_the_clouds_and_is_refused_where_it_does_not_apply(
        self, mapctl: Mapctl, tmp_path: Path
    ) -> None:
        points = np.array([[1.0, 2.0, 3.0]], np.float32)
        moves = [(1, (4.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0))]
        bag = tf_bag(tmp_path / "run", moves, [(1, "lidar", points)])
        boxes = {}
        for frame in ("odom", "lidar"):
            info = mapctl.json("import", str(bag), "--tf-frame", frame, "--mission", f"{frame}-")
            (cloud,) = [m for m in info["missions"] if m["points"]]
            boxes[frame] = cloud["bbox"]
        # the lidar sits 0.5 m ahead of base_link and 0.3 m up, base_link 4 m along odom's x
        assert boxes["lidar"] == pytest.approx([1, 2, 3, 1, 2, 3])
        assert boxes["odom"] == pytest.approx([5.5, 2, 3.3, 5.5, 2, 3.3])
        commits = len(mapctl.json("log"))
        unknown = mapctl.main("import", str(bag), "--tf-frame", "map")
        assert unknown.code == EXIT_USAGE
        assert "--tf-frame map: no transform names it" in unknown.err
        elsewhere = mapctl.main("import", str(LOG), "--tf-frame", "odom")
        assert elsewhere.code == EXIT_USAGE
        assert "--tf-frame applies to ROS bags only" in elsewhere.err
        assert len(mapctl.json("log")) == commits  # neither committed anything

    def test_a_cloud_tf_cannot_place_is_kept_and_reported(
        self, mapctl: Mapctl, tmp_path: Path
    ) -> None:
        points = np.array([[1.0, 2.0, 3.0]], np.float32)
        moves = [(1, (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0))]
        bag = tf_bag(tmp_path / "lost", moves, [(1, "camera", points)], mount=None)
        info = mapctl.json("import", str(bag))
        warnings = {m["name"]: m["warnings"] for m in info["missions"]}
        assert warnings["lost-odom"] == []
        (warning,) = warnings["lost-points"]
        assert warning.startswith("topic /points: no TF path from camera to odom")
        outcome = mapctl.main("import", str(bag), "--mission", "again-")
        assert outcome.code == 0
        assert outcome.err_lines[-1].startswith(
            "again-points: topic /points: no TF path from camera to odom"
        )


def read_pgm(path: Path) -> np.ndarray:
    """A binary PGM's pixels (rows x columns), row 0 the top."""
    data = path.read_bytes()
    magic, _comment, size, _depth, pixels = data.split(b"\n", 4)
    assert magic == b"P5"
    width, height = map(int, size.split())
    return np.frombuffer(pixels, dtype=np.uint8).reshape(height, width)


class TestGrid:
    def test_a_bag_grid_round_trips_to_nav2(self, mapctl: Mapctl, tmp_path: Path) -> None:
        bag = write_bag(tmp_path / "run", "mcap", poses=3, grid=True)
        imported = mapctl.json("import", str(bag), "--topics", "/map")
        (mission,) = imported["missions"]
        assert (mission["name"], mission["bbox"]) == ("run-map", [-7.5, -5.0, 0.0, 7.5, 5.0, 0.0])
        assert "grids" in mission["chunks"]
        assert [m["kind"] for m in mapctl.json("missions")["missions"]] == ["grid"]
        info = mapctl.json("grid", "-o", str(tmp_path / "map.yaml"))
        assert (info["missions"], info["scans"], info["without_scans"]) == (["run-map"], 0, [])
        cells = room_cells()
        want = np.full(cells.shape, 205, np.uint8)
        want[cells >= 65] = 0
        want[(cells >= 0) & (cells < 25)] = 254
        pixels = read_pgm(tmp_path / "map.pgm")
        assert np.array_equal(pixels, want[::-1])  # the PGM's first row is the top
        yaml = (tmp_path / "map.yaml").read_text()
        assert "resolution: 0.05\n" in yaml
        assert f"origin: [{GRID_ORIGIN[0]!r}, {GRID_ORIGIN[1]!r}, 0.0]" in yaml
        assert info["cells"]["unknown"] == int(np.count_nonzero(want == 205))

    def test_a_box_crops_and_refusals(self, mapctl: Mapctl, tmp_path: Path) -> None:
        bag = write_bag(tmp_path / "run.bag", "ros1", poses=3, grid=True)
        imported = mapctl.json("import", str(bag))
        tiles = {m["name"]: m["chunks"].get("grids") for m in imported["missions"]}["run-map"]
        found = mapctl.json("query-bbox", "-t", "grids", "1", "1", "0", "2", "2", "0")["results"]
        assert [(r["chunk"], r["missions"]) for r in found] == [(tiles, ["run-map"])]
        box = ("--bbox", "-7.5", "-5", "0", "-2.5", "0", "0")  # the room's lower-left 100 x 100
        info = mapctl.json("grid", "-o", str(tmp_path / "box.yaml"), "-m", "run-map", *box)
        assert (info["width"], info["height"], info["origin"]) == (100, 100, [-7.5, -5.0, 0.0])
        assert read_pgm(tmp_path / "box.pgm")[-1, 0] == 0  # the corner wall
        out = str(tmp_path / "x.yaml")
        finer = mapctl.main("grid", "-o", out, "-m", "run-map", "--resolution", "0.1")
        assert finer.code == EXIT_USAGE
        assert "grids of 0.05 m a cell, not 0.1 m" in finer.err
        mixed = mapctl.main("grid", "-o", out, "-m", "run-*")
        assert mixed.code == EXIT_USAGE
        assert "not both; choose one kind with -m" in mixed.err
        world = mapctl.main("grid", "-o", out, "-m", "run-map", "--frame", "world")
        assert world.code == EXIT_USAGE
        assert "has no place in the world frame yet" in world.err


class TestExport:
    def test_a_trajectory_round_trips_through_a_bag(self, mapctl: Mapctl, tmp_path: Path) -> None:
        mapctl("import", str(write_bag(tmp_path / "run", "sqlite3", poses=30)))
        out = tmp_path / "out"
        info = mapctl.json("export", "run-odom", "-o", str(out), "--format", "bag")
        assert info == {
            "mission": "run-odom",
            "path": str(out),
            "format": "bag",
            "frame": "mission",
            "poses": 30,
            "points": 0,
            "grid_cells": 0,
            "time": "timestamp",
            "topics": ["/run_odom/pose", "/run_odom/path"],
        }
        assert (out / "out.mcap").is_file()
        topics = read_back(out)
        stored = tum_rows(mapctl, "run-odom", tmp_path)
        poses = [message for _, message in topics["/run_odom/pose"]]
        (path_message,) = [message for _, message in topics["/run_odom/path"]]
        assert len(poses) == len(path_message.poses) == len(stored)
        for row, pose, in_path in zip(stored, poses, path_message.poses, strict=True):
            p, q = pose.pose.position, pose.pose.orientation
            assert [p.x, p.y, p.z, q.x, q.y, q.z, q.w] == row[1:]  # bit for bit
            stamp = pose.header.stamp.sec + pose.header.stamp.nanosec * 1e-9
            assert stamp == pytest.approx(row[0], abs=1e-6)
            assert pose.header.frame_id == "run-odom/odom"
            assert in_path.pose.position.x == p.x
        again = mapctl.json("import", str(out), "--mission", "back-")
        assert [m["vertices"] for m in again["missions"]] == [30, 30]

    def test_a_grid_round_trips_through_a_bag(self, mapctl: Mapctl, tmp_path: Path) -> None:
        mapctl("import", str(write_bag(tmp_path / "run", "mcap", poses=5, grid=True)))
        out = tmp_path / "out"
        info = mapctl.json("export", "run-map", "-o", str(out), "--format", "bag")
        cells = room_cells()  # 300 x 200: two tiles wide
        assert (info["grid_cells"], info["poses"], info["topics"]) == (
            cells.size,
            0,
            ["/run_map/map"],
        )
        ((ns, grid),) = read_back(out)["/run_map/map"]
        assert grid.header.frame_id == "run-map/map"
        assert ns == 1_700_000_000_400_000_000  # the stored grid's stamp, as recorded
        assert (grid.header.stamp.sec, grid.header.stamp.nanosec) == (1_700_000_000, 400_000_000)
        assert (grid.info.width, grid.info.height) == (300, 200)
        assert grid.info.resolution == np.float32(0.05)
        origin = grid.info.origin
        assert (origin.position.x, origin.position.y, origin.position.z) == GRID_ORIGIN[:3]
        assert (origin.orientation.z, origin.orientation.w) == (0.0, 1.0)
        assert np.array_equal(np.asarray(grid.data).reshape(200, 300), cells)
        again = mapctl.json("import", str(out), "--mission", "back-")
        (mission,) = again["missions"]
        assert (mission["name"], mission["bbox"]) == ("back-run_map-map", [-7.5, -5, 0, 7.5, 5, 0])
        mapctl("grid", "-o", str(tmp_path / "a.yaml"), "-m", "run-map")
        mapctl("grid", "-o", str(tmp_path / "b.yaml"), "-m", "back-run_map-map")
        assert (tmp_path / "a.pgm").read_bytes() == (tmp_path / "b.pgm").read_bytes()

    def test_laser_scans_become_clouds_stamped_by_their_pose(
        self, mapctl: Mapctl, tmp_path: Path
    ) -> None:
        mapctl("import", str(LOG), "--mission", "lab")
        out = tmp_path / "lab"
        info = mapctl.json("export", "lab", "-o", str(out), "--format", "bag")
        assert (info["poses"], info["points"]) == (671, 109_635)
        topics = read_back(out)
        clouds = topics["/lab/cloud"]
        pose_times = {ns for ns, _ in topics["/lab/pose"]}
        assert {ns for ns, _ in clouds} <= pose_times
        points = sum(m.width for _, m in clouds)
        assert points == 109_635
        first = np.frombuffer(clouds[0][1].data.tobytes(), "<f4").reshape(-1, 3)
        assert np.isfinite(first).all()

    def test_refusals(self, mapctl: Mapctl, tmp_path: Path) -> None:
        mapctl("import", str(write_bag(tmp_path / "run.bag", "ros1", poses=3)))
        world = mapctl.main(
            "export", "run-odom", "-o", str(tmp_path / "w"), "--format", "bag", "--frame", "world"
        )
        assert world.code == EXIT_USAGE
        assert "no place in the world frame yet" in world.err
        (tmp_path / "taken").write_text("")
        taken = mapctl.main("export", "run-odom", "-o", str(tmp_path / "taken"), "--format", "bag")
        assert taken.code == EXIT_USAGE
        assert "a bag is a new folder" in taken.err
        unnamed = mapctl.main("export", "run-odom", "-o", str(tmp_path / "folder"))
        assert unnamed.code == EXIT_USAGE

    def test_the_world_frame_moves_the_poses_as_tum_does(
        self, mapctl: Mapctl, tmp_path: Path
    ) -> None:
        pytest.importorskip("gtsam", reason="the registration extra (make test installs it)")
        mapctl("import", str(TUNNELS))
        mapctl("align", "-m", "robot1", "-m", "robot3", "--anchor", "robot3")
        out = tmp_path / "world"
        info = mapctl.json(
            "export", "robot1", "-o", str(out), "--format", "bag", "--frame", "world"
        )
        assert (info["frame"], info["time"]) == ("world", "index")
        stored = tum_rows(mapctl, "robot1", tmp_path, "--frame", "world")
        poses = [message for _, message in read_back(out)["/robot1/pose"]]
        assert {p.header.frame_id for p in poses} == {"world"}
        got = [[m.pose.position.x, m.pose.position.y, m.pose.position.z] for m in poses]
        assert got == [row[1:4] for row in stored]
