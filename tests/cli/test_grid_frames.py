"""Stored occupancy grids in the world frame (issue 17 §4): a bag's grid mission
placed there by a `frames` row is resampled into the world's axes, each world
cell taking the stored cell its centre falls in; unplaced and tilted places
are refused. On real repositories, with bags written by `rosbags`."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from mapapi.maps.alignment import pose_matrix
from mapapi.maps.se3 import Pose
from mapbench.bags import GRID_ORIGIN, GRID_RESOLUTION, room_cells, write_bag
from tests.cli.conftest import Mapctl
from tests.unit.grid_bags import write_grid_bag
from tests.unit.nav2_maps import read_pgm

pytest.importorskip("rosbags")

EXIT_USAGE = 2
TURN = math.radians(30)
PLACE: Pose = (20.0, 10.0, 0.5, 0.0, 0.0, math.sin(TURN / 2), math.cos(TURN / 2))


def place(mapctl: Mapctl, mission: str, pose: Pose) -> None:
    """Give `mission` a place in the world frame: a `frames` row in its frames chunk."""
    listed = mapctl.json("missions")["missions"]
    (chunk,) = [m["chunks"]["frames"] for m in listed if m["name"] == mission]
    transform = dict(zip(("x", "y", "z", "qx", "qy", "qz", "qw"), pose, strict=True))
    row = {"mission": mission, "frame": "world", "transform": transform}
    mapctl("set", "frames", json.dumps(row), "--chunk", chunk)
    mapctl("commit", "-m", f"place {mission} in the world")


def nav2(cells: np.ndarray) -> np.ndarray:
    """nav2's pixels of occupancy cells (row 0 the bottom), row 0 the top."""
    pixels = np.full(cells.shape, 205, np.uint8)
    pixels[cells >= 65] = 0
    pixels[(cells >= 0) & (cells < 25)] = 254
    return pixels[::-1]


def sampled(info: dict, cells: np.ndarray, move: np.ndarray) -> np.ndarray:
    """The grid `info` describes, each cell the one of `cells` that its centre
    falls in, moved back by the inverse of `move` (the 4x4 matrix that takes the
    cells' frame, their corner at its origin, to the grid's): the definition,
    cell by cell."""
    side = info["resolution"]
    x0, y0, _ = info["origin"]
    xs = x0 + (np.arange(info["width"]) + 0.5) * side
    ys = y0 + (np.arange(info["height"]) + 0.5) * side
    gx, gy = np.meshgrid(xs, ys)  # row 0 the bottom
    world = np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, move[2, 3]), np.ones(gx.size)])
    local = np.linalg.inv(move) @ world
    col = np.floor(local[0] / side).astype(int)
    row = np.floor(local[1] / side).astype(int)
    height, width = cells.shape
    inside = (col >= 0) & (col < width) & (row >= 0) & (row < height)
    out = np.full(gx.size, -1, np.int8)
    out[inside] = cells[row[inside], col[inside]]
    return nav2(out.reshape(gx.shape))


def footprint(move: np.ndarray, width: float, height: float) -> list[float]:
    """xmin, ymin, xmax, ymax around a `width` x `height` rectangle from the origin, moved."""
    corners = np.array([move @ [x, y, 0.0, 1.0] for x in (0, width) for y in (0, height)])
    return [*corners[:, :2].min(axis=0), *corners[:, :2].max(axis=0)]


@pytest.fixture
def rover(mapctl: Mapctl, tmp_path: Path) -> Mapctl:
    """A repository holding a bag's trajectories and its grid, run-map."""
    mapctl("import", str(write_bag(tmp_path / "run.bag", "ros1", poses=5, grid=True)))
    return mapctl


class TestWorldFrame:
    def test_a_placed_grid_is_resampled_into_the_worlds_axes(
        self, rover: Mapctl, tmp_path: Path
    ) -> None:
        place(rover, "run-map", PLACE)
        out = tmp_path / "world.yaml"
        info = rover.json("grid", "-m", "run-map", "-o", str(out), "--frame", "world")

        # the box around the turned room: its lowest corner, then its leftmost
        move = pose_matrix(PLACE) @ pose_matrix(GRID_ORIGIN)
        assert info["origin"][:2] == pytest.approx(footprint(move, 15, 10)[:2], abs=1e-9)
        assert (info["frame"], info["width"], info["height"]) == ("world", 360, 323)
        want = sampled(info, room_cells(), move)
        assert np.array_equal(read_pgm(out.with_suffix(".pgm")), want)
        assert info["cells"]["occupied"] == int(np.count_nonzero(want == 0))

        again = tmp_path / "e.yaml"
        exported = rover.json("export", "run-map", "-o", str(again), "--frame", "world")
        assert exported["scans"] == 0
        assert read_pgm(tmp_path / "e.pgm").tobytes() == want.tobytes()

    def test_an_unplaced_or_tilted_grid_is_refused(self, rover: Mapctl, tmp_path: Path) -> None:
        target = str(tmp_path / "x.yaml")
        unplaced = rover.main("grid", "-m", "run-map", "-o", target, "--frame", "world")
        assert unplaced.code == EXIT_USAGE
        assert "mission 'run-map' has no place in the world frame yet" in unplaced.err
        assert "`mapctl set frames`" in unplaced.err
        roll = math.radians(2)
        place(rover, "run-map", (0.0, 0.0, 0.0, math.sin(roll / 2), 0.0, 0.0, math.cos(roll / 2)))
        tilted = rover.main("grid", "-m", "run-map", "-o", target, "--frame", "world")
        assert tilted.code == EXIT_USAGE
        assert "the place of 'run-map' in the world tilts the plane by 2.000 degrees" in tilted.err
        assert not Path(target).exists()
        plain = rover.json("grid", "-m", "run-map", "-o", target)  # its own frame still works
        assert (plain["origin"], plain["resolution"]) == ([-7.5, -5.0, 0.0], GRID_RESOLUTION)


class TestTurnedOrigin:
    def test_a_grid_turned_at_its_origin_is_imported_and_written_along_the_axes(
        self, mapctl: Mapctl, tmp_path: Path
    ) -> None:
        yaw = math.radians(30)
        origin: Pose = (1.0, 2.0, 0.0, 0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
        cells = room_cells(600, 300)  # 30 x 15 m: tiles of 256 cells, 3 x 2 of them
        bag = write_grid_bag(tmp_path / "floor", cells, origin)
        (mission,) = mapctl.json("import", str(bag))["missions"]
        move = pose_matrix(origin)
        box = footprint(move, 30, 15)
        assert mission["bbox"] == pytest.approx([box[0], box[1], 0, box[2], box[3], 0])
        # inside the turned map near its far corner, and inside the box the unturned map
        # would have had but outside the turned one: the tiles lie at their turned boxes
        inside = mapctl.json("query-bbox", "-t", "grids", "18.5", "28.5", "0", "19.4", "29.5", "0")
        assert [r["missions"] for r in inside["results"]] == [["floor-map"]]
        outside = mapctl.json("query-bbox", "-t", "grids", "29.5", "2.5", "0", "30.5", "3.5", "0")
        assert outside["results"] == []

        info = mapctl.json("grid", "-m", "floor-map", "-o", str(tmp_path / "floor.yaml"))
        assert info["origin"][:2] == pytest.approx(box[:2], abs=1e-9)
        want = sampled(info, cells, move)
        assert np.array_equal(read_pgm(tmp_path / "floor.pgm"), want)
        assert (want == 0).sum() > 0.9 * (nav2(cells) == 0).sum()  # most walls survive

        place(mapctl, "floor-map", PLACE)  # and its place in the world on top of its turn
        world = mapctl.json(
            "grid", "-m", "floor-map", "-o", str(tmp_path / "w.yaml"), "--frame", "world"
        )
        assert np.array_equal(
            read_pgm(tmp_path / "w.pgm"), sampled(world, cells, pose_matrix(PLACE) @ move)
        )
