"""Occupancy grids as tiles (`mapapi.maps.occupancy`): cut into tiles, composed
back over any box of their resolution, and mapped to nav2's pixels."""

from __future__ import annotations

import numpy as np

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
