"""Occupancy grids as map data (issue 17 §3): a ROS `nav_msgs/OccupancyGrid` as
a mission of grid tiles, and the tiles composed back into one raster.

An `OccupancyGrid` is an axis-aligned raster of int8 occupancy in its mission's
frame, as ROS gives it: -1 unknown, 0 (free) to 100 (occupied), row 0 the
bottom (lowest y). It is stored cut into tiles of at most `TILE_SIDE` cells a
side (`grid_tiles`), each a `GridTile` row placed in the spatial index at its
box, so a box query finds the part of a large map it overlaps.

`compose_tiles` puts tiles back into any raster of the same resolution: each
tile cell lands in the raster cell holding its centre, so grids whose origins
are not on the raster's lattice still land in the nearest cell, and a raster
cell no tile covers stays unknown. `nav2_pixels` maps occupancy to nav2's
trinary pixels with the thresholds `mapctl grid` casts with (`mapapi.maps.grid`).
Pure: numpy only.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from mapapi.lookup.spatial import BBox
from mapapi.maps.grid import FREE, FREE_P, OCCUPIED, OCCUPIED_P, UNKNOWN, GridSpec
from mapapi.maps.schema import GridTile, box_to_pb

Cells = npt.NDArray[np.int8]  # (height, width), row 0 the bottom

TILE_SIDE = 256
"""Cells a tile has at most along a side: 64 KiB of cells a row."""


@dataclass
class OccupancyGrid:
    """One occupancy grid mission, as a bag's message gives it.

    Attributes:
        name: the mission's name.
        robot: the robot that made it.
        frame: the frame it lies in.
        resolution: a cell's side, metres.
        x0, y0, z: its lower-left corner (column 0, row 0) in `frame`.
        cells: int8 occupancy, (height, width), row 0 the bottom.
        stamp: the message's header stamp, seconds.
    """

    name: str
    robot: str
    frame: str
    resolution: float
    x0: float
    y0: float
    z: float
    cells: Cells
    stamp: float = 0.0

    def bbox(self) -> BBox:
        """The box of its cells (flat, at `z`)."""
        height, width = self.cells.shape
        return self.cells_box(0, 0, width, height)

    def cells_box(self, col: int, row: int, width: int, height: int) -> BBox:
        """The box of `width` x `height` cells from column `col`, row `row`."""
        side = self.resolution
        x, y = self.x0 + col * side, self.y0 + row * side
        return BBox(x, y, self.z, x + width * side, y + height * side, self.z)

    def known(self) -> int:
        """How many of its cells are known (not -1)."""
        return int(np.count_nonzero(self.cells >= 0))


def grid_tiles(grid: OccupancyGrid) -> list[GridTile]:
    """The grid's `GridTile` rows: `TILE_SIDE`-cell squares from its corner, the
    last of each row and column narrower."""
    height, width = grid.cells.shape
    tiles = []
    for row in range(0, height, TILE_SIDE):
        for col in range(0, width, TILE_SIDE):
            part = grid.cells[row : row + TILE_SIDE, col : col + TILE_SIDE]
            rows, cols = part.shape
            box = grid.cells_box(col, row, cols, rows)
            tiles.append(
                GridTile(
                    mission=grid.name,
                    resolution=grid.resolution,
                    x=box.xmin,
                    y=box.ymin,
                    width=cols,
                    height=rows,
                    cells=np.ascontiguousarray(part, dtype=np.int8).tobytes(),
                    bbox=box_to_pb(box),
                    stamp=grid.stamp,
                )
            )
    return tiles


def tile_cells(tile: GridTile) -> Cells:
    """A tile's cells, (height, width), row 0 the bottom.

    Raises:
        ValueError: its bytes do not fill width x height cells.
    """
    if len(tile.cells) != tile.width * tile.height:
        raise ValueError(
            f"grid tile of {tile.mission!r} at ({tile.x}, {tile.y}) holds {len(tile.cells)} "
            f"cells, not {tile.width} x {tile.height}"
        )
    return np.frombuffer(tile.cells, dtype=np.int8).reshape(tile.height, tile.width)


def tiles_box(tiles: Iterable[GridTile]) -> BBox:
    """The box around the tiles' cells."""
    return BBox.enclosing(
        [
            BBox(t.x, t.y, 0.0, t.x + t.width * t.resolution, t.y + t.height * t.resolution, 0.0)
            for t in tiles
        ]
    )


def compose_tiles(tiles: Sequence[GridTile], spec: GridSpec) -> Cells:
    """The occupancy of the raster `spec` (row 0 the bottom) from `tiles` of its
    resolution: each tile cell in the raster cell holding its centre (a later
    tile overwrites an earlier one where they overlap); -1 where none lands."""
    out = np.full((spec.height, spec.width), -1, dtype=np.int8)
    for tile in tiles:
        cells = tile_cells(tile)
        side = spec.resolution
        cols = np.floor((tile.x + (np.arange(tile.width) + 0.5) * side - spec.x0) / side)
        rows = np.floor((tile.y + (np.arange(tile.height) + 0.5) * side - spec.y0) / side)
        keep_c = (cols >= 0) & (cols < spec.width)
        keep_r = (rows >= 0) & (rows < spec.height)
        if keep_c.any() and keep_r.any():
            target = np.ix_(rows[keep_r].astype(np.int64), cols[keep_c].astype(np.int64))
            out[target] = cells[np.ix_(keep_r, keep_c)]
    return out


def nav2_pixels(cells: Cells) -> npt.NDArray[np.uint8]:
    """nav2's trinary picture of occupancy (row 0 the top, as a PGM's): at least
    65 occupied (0), 0 to 24 free (254), else or unknown (-1) 205: the shares
    `mapctl grid` casts scans with, as percentages."""
    pixels = np.full(cells.shape, UNKNOWN, dtype=np.uint8)
    pixels[cells >= round(OCCUPIED_P * 100)] = OCCUPIED
    pixels[(cells >= 0) & (cells < round(FREE_P * 100))] = FREE
    return pixels[::-1]
