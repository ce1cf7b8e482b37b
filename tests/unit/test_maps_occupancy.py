"""Occupancy grids as tiles (`mapapi.maps.occupancy`): cut into tiles, composed
back over any box of their resolution, and mapped to nav2's pixels."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mapapi.maps.grid import FREE, OCCUPIED, UNKNOWN, GridSpec
from mapapi.maps.occupancy import (
    TILE_SIDE,
    OccupancyGrid,
    compose_tiles,
    grid_tiles,
    nav2_pixels,
    tile_cells,
    tiles_box,
)


def a_grid(width: int, height: int, x0: float = -3.0, y0: float = 2.0) -> OccupancyGrid:
    """A grid of cells counting through -1..100, so every cell tells where it came from."""
    cells = (np.arange(width * height) % 102 - 1).astype(np.int8).reshape(height, width)
    return OccupancyGrid("m", "r", "m/map", 0.1, x0, y0, 0.5, cells, 12.5)


class TestTiles:
    def test_tiles_cut_at_256_cells_and_compose_back(self) -> None:
        grid = a_grid(2 * TILE_SIDE + 10, TILE_SIDE + 1)
        tiles = grid_tiles(grid)
        assert [(t.width, t.height) for t in tiles] == [
            (256, 256),
            (256, 256),
            (10, 256),
            (256, 1),
            (256, 1),
            (10, 1),
        ]
        assert {(t.mission, t.stamp) for t in tiles} == {("m", 12.5)}
        second = tiles[1]
        assert (second.x, second.y) == (-3.0 + 25.6, 2.0)
        assert (second.bbox.xmax, second.bbox.zmin, second.bbox.zmax) == (-3.0 + 51.2, 0.5, 0.5)
        assert np.array_equal(tile_cells(second), grid.cells[:256, 256:512])
        box = tiles_box(tiles)
        assert (box.xmin, box.ymin) == (-3.0, 2.0)
        height, width = grid.cells.shape
        spec = GridSpec(-3.0, 2.0, 0.1, width, height)
        assert np.array_equal(compose_tiles(tiles, spec), grid.cells)

    def test_a_box_crops_and_pads_with_unknown(self) -> None:
        grid = a_grid(20, 10, x0=0.0, y0=0.0)
        spec = GridSpec(-0.5, 0.5, 0.1, 10, 10)  # 5 columns left of the grid, 5 rows up
        out = compose_tiles(grid_tiles(grid), spec)
        assert (out[:, :5] == -1).all()
        assert (out[5:, :] == -1).all()
        assert np.array_equal(out[:5, 5:], grid.cells[5:10, 0:5])


def test_nav2_pixels_map_occupancy_by_thresholds() -> None:
    cells = np.array([[-1, 0, 24, 25], [64, 65, 100, 50]], dtype=np.int8)
    pixels = nav2_pixels(cells)
    # row 0 of a PGM is the top: the grid's last row
    assert pixels.tolist() == [
        [UNKNOWN, OCCUPIED, OCCUPIED, UNKNOWN],
        [UNKNOWN, FREE, FREE, UNKNOWN],
    ]


class TestTurned:
    def test_tiles_of_a_turned_grid_keep_its_yaw_and_lie_at_their_turned_boxes(self) -> None:
        yaw = math.radians(30)
        grid = a_grid(TILE_SIDE + 20, 30)
        turned = OccupancyGrid("m", "r", "m/map", 0.1, 1.0, 2.0, 0.5, grid.cells, 0.0, yaw)
        tiles = grid_tiles(turned)
        assert [(t.width, t.height, t.yaw) for t in tiles] == [(256, 30, yaw), (20, 30, yaw)]
        turn = np.array([[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]])
        second = tiles[1]  # its corner 25.6 m along the turned x axis
        assert (second.x, second.y) == pytest.approx(tuple(turn @ [25.6, 0.0] + [1.0, 2.0]))
        corners = np.array([[25.6, 0.0], [27.6, 0.0], [25.6, 3.0], [27.6, 3.0]]) @ turn.T + [1, 2]
        box = second.bbox
        assert [box.xmin, box.ymin, box.xmax, box.ymax] == pytest.approx(
            [*corners.min(axis=0), *corners.max(axis=0)]
        )
        assert (box.zmin, box.zmax) == (0.5, 0.5)
        whole = tiles_box(tiles)
        left, top = turn @ [0.0, 3.0] + [1, 2], turn @ [27.6, 3.0] + [1, 2]  # turned corners
        assert (whole.xmin, whole.ymax) == pytest.approx((left[0], top[1]))
        assert turned.bbox().as_tuple() == pytest.approx(
            (whole.xmin, whole.ymin, 0.5, whole.xmax, whole.ymax, 0.5)
        )

    def test_a_turned_grid_composes_by_the_cell_each_centre_falls_in(self) -> None:
        yaw = math.radians(-40)
        cells = a_grid(37, 23).cells
        turned = OccupancyGrid("m", "r", "m/map", 0.1, -1.0, 0.5, 0.0, cells, 0.0, yaw)
        spec = GridSpec(-2.0, -3.0, 0.1, 60, 50)
        out = compose_tiles(grid_tiles(turned), spec)
        # each raster cell's centre, turned back into the grid: the cell it falls in
        xs = -2.0 + (np.arange(60) + 0.5) * 0.1 + 1.0
        ys = -3.0 + (np.arange(50) + 0.5) * 0.1 - 0.5
        gx, gy = np.meshgrid(xs, ys)
        col = np.floor((math.cos(yaw) * gx + math.sin(yaw) * gy) / 0.1).astype(int)
        row = np.floor((-math.sin(yaw) * gx + math.cos(yaw) * gy) / 0.1).astype(int)
        inside = (col >= 0) & (col < 37) & (row >= 0) & (row < 23)
        want = np.full((50, 60), -1, np.int8)
        want[inside] = cells[row[inside], col[inside]]
        assert np.array_equal(out, want)
        assert inside.sum() > 0.8 * cells.size  # most of it lands in the box
