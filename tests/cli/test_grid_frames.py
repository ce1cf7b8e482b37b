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
from tests.unit.nav2_maps import read_pgm

pytest.importorskip("rosbags")

EXIT_USAGE = 2
TURN = math.radians(30)
PLACE: Pose = (20.0, 10.0, 0.5, 0.0, 0.0, math.sin(TURN / 2), math.cos(TURN / 2))


def place(mapctl: Mapctl, mission: str, pose: Pose) -> None:
    """Give `mission` a place in the world frame: a `frames` row in a chunk of its own."""
    chunk = mapctl.json("chunk", "create", "frames")["id"]
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


def sampled(info: dict, cells: np.ndarray, corner: tuple[float, float], pose: Pose) -> np.ndarray:
    """The grid `info` describes, each cell the one of `cells` (corner at `corner`
    in the mission's frame) that its centre falls in, moved back from the world
    by the inverse of `pose`'s 4x4 matrix: the definition, cell by cell."""
    side = info["resolution"]
    x0, y0, _ = info["origin"]
    xs = x0 + (np.arange(info["width"]) + 0.5) * side
    ys = y0 + (np.arange(info["height"]) + 0.5) * side
    gx, gy = np.meshgrid(xs, ys)  # row 0 the bottom
    world = np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, pose[2]), np.ones(gx.size)])
    local = np.linalg.inv(pose_matrix(pose)) @ world
    col = np.floor((local[0] - corner[0]) / side).astype(int)
    row = np.floor((local[1] - corner[1]) / side).astype(int)
    height, width = cells.shape
    inside = (col >= 0) & (col < width) & (row >= 0) & (row < height)
    out = np.full(gx.size, -1, np.int8)
    out[inside] = cells[row[inside], col[inside]]
    return nav2(out.reshape(gx.shape))


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
        move = pose_matrix(PLACE)
        corners = [(x, y) for x in (-7.5, 7.5) for y in (-5.0, 5.0)]
        moved = np.array([(move @ [x, y, 0.0, 1.0])[:2] for x, y in corners])
        assert info["origin"][:2] == pytest.approx(list(moved.min(axis=0)), abs=1e-9)
        assert (info["frame"], info["width"], info["height"]) == ("world", 360, 323)
        want = sampled(info, room_cells(), GRID_ORIGIN[:2], PLACE)
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
