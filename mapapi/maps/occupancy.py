"""Occupancy grids as map data (issue 17 §3): a ROS `nav_msgs/OccupancyGrid` as
a mission of grid tiles, and the tiles composed back into one raster.

An `OccupancyGrid` is a raster of int8 occupancy in its mission's frame, as
ROS gives it: -1 unknown, 0 (free) to 100 (occupied), row 0 the bottom, its
columns along the frame's x turned by its origin's yaw (0 for most maps). It
is stored cut into tiles of at most `TILE_SIDE` cells a side (`grid_tiles`),
each a `GridTile` row (with the yaw) placed in the spatial index at the box
around its turned footprint, so a box query finds the part of a large map it
overlaps.

`compose_tiles` puts tiles back into any raster of the same resolution along
its frame's axes, each tile moved by its mission's place there if any (the
world frame: `mapapi.maps.plane`): a raster cell takes the tile cell its
centre falls in, so grids whose origins are not on the raster's lattice, or
turned, land in the nearest cells, and a raster cell no tile covers stays
unknown. `nav2_pixels` maps occupancy to nav2's trinary pixels with the
thresholds `mapctl grid` casts with (`mapapi.maps.grid`). Pure: numpy only.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from mapapi.lookup.spatial import BBox
from mapapi.maps.grid import FREE, FREE_P, OCCUPIED, OCCUPIED_P, UNKNOWN, GridSpec
from mapapi.maps.plane import Placement
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
        yaw: its origin's turn about z, radians: its columns run along `frame`'s
            x turned by it.
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
    yaw: float = 0.0

    def bbox(self) -> BBox:
        """The box around its cells (flat, at `z`)."""
        height, width = self.cells.shape
        return self.cells_box(0, 0, width, height)

    def corner(self, col: int, row: int) -> Placement:
        """Where the cells from column `col`, row `row` on lie: that cell's
        lower-left corner, turned as the grid is."""
        side = self.resolution
        ((x, y),) = Placement(self.x0, self.y0, self.yaw).apply(
            np.array([[col * side, row * side]])
        )
        return Placement(float(x), float(y), self.yaw)

    def cells_box(self, col: int, row: int, width: int, height: int) -> BBox:
        """The box around `width` x `height` cells from column `col`, row `row`."""
        side = self.resolution
        return footprint_box(self.corner(col, row), width * side, height * side, self.z)

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
            where = grid.corner(col, row)
            tiles.append(
                GridTile(
                    mission=grid.name,
                    resolution=grid.resolution,
                    x=where.x,
                    y=where.y,
                    yaw=grid.yaw,
                    width=cols,
                    height=rows,
                    cells=np.ascontiguousarray(part, dtype=np.int8).tobytes(),
                    bbox=box_to_pb(grid.cells_box(col, row, cols, rows)),
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


Places = Mapping[str, Placement]
"""Mission -> where its frame lies in the frame a raster is composed in (none: there)."""


def tile_placement(tile: GridTile, places: Places | None = None) -> Placement:
    """Where the tile's cells lie: its column 0, row 0 corner and its turn, in
    its mission's frame, moved by the mission's place in `places` if any."""
    own = Placement(tile.x, tile.y, tile.yaw)
    place = (places or {}).get(tile.mission)
    return own if place is None else own.then(place)


def footprint_box(where: Placement, width: float, height: float, z: float = 0.0) -> BBox:
    """The box around a rectangle of `width` x `height` metres from its corner,
    moved by `where` (its corners' box: larger than it when turned)."""
    corners = where.apply(np.array([[0.0, 0.0], [width, 0.0], [0.0, height], [width, height]]))
    (xmin, ymin), (xmax, ymax) = corners.min(axis=0), corners.max(axis=0)
    return BBox(float(xmin), float(ymin), z, float(xmax), float(ymax), z)


def tiles_box(tiles: Iterable[GridTile], places: Places | None = None) -> BBox:
    """The box around the tiles' cells, each moved by its mission's place in `places`."""
    return BBox.enclosing(
        [
            footprint_box(
                tile_placement(t, places), t.width * t.resolution, t.height * t.resolution
            )
            for t in tiles
        ]
    )


def compose_tiles(tiles: Sequence[GridTile], spec: GridSpec, places: Places | None = None) -> Cells:
    """The occupancy of the raster `spec` (row 0 the bottom) from `tiles` of its
    resolution, each moved by its mission's place in `places`: a raster cell
    takes the tile cell its centre lies in (a later tile overwrites an earlier
    one where they overlap); -1 where none lands."""
    out = np.full((spec.height, spec.width), -1, dtype=np.int8)
    for tile in tiles:
        where = tile_placement(tile, places)
        if where.yaw == 0.0:
            _paste_aligned(out, tile_cells(tile), spec, where)
        else:
            _paste_turned(out, tile_cells(tile), spec, where)
    return out


def _paste_aligned(out: Cells, cells: Cells, spec: GridSpec, where: Placement) -> None:
    """`compose_tiles` of cells whose axes are the raster's: each cell lands in
    the raster cell holding its centre (the cell whose centre it holds: the same
    cells, found a row and a column at a time)."""
    side = spec.resolution
    height, width = cells.shape
    cols = np.floor((where.x + (np.arange(width) + 0.5) * side - spec.x0) / side)
    rows = np.floor((where.y + (np.arange(height) + 0.5) * side - spec.y0) / side)
    keep_c = (cols >= 0) & (cols < spec.width)
    keep_r = (rows >= 0) & (rows < spec.height)
    if keep_c.any() and keep_r.any():
        target = np.ix_(rows[keep_r].astype(np.int64), cols[keep_c].astype(np.int64))
        out[target] = cells[np.ix_(keep_r, keep_c)]


def _paste_turned(out: Cells, cells: Cells, spec: GridSpec, where: Placement) -> None:
    """`compose_tiles` of turned cells: each raster cell over their footprint
    takes the cell its centre lies in, found by moving the centre back through
    `where` (nearest neighbour: a turned cell covers no raster cell exactly)."""
    side = spec.resolution
    height, width = cells.shape
    box = footprint_box(where, width * side, height * side)
    c0 = max(0, int(np.floor((box.xmin - spec.x0) / side)))
    r0 = max(0, int(np.floor((box.ymin - spec.y0) / side)))
    c1 = min(spec.width, int(np.ceil((box.xmax - spec.x0) / side)))
    r1 = min(spec.height, int(np.ceil((box.ymax - spec.y0) / side)))
    if c0 >= c1 or r0 >= r1:
        return
    dx = spec.x0 + (np.arange(c0, c1) + 0.5) * side - where.x  # centres from the corner
    dy = spec.y0 + (np.arange(r0, r1) + 0.5) * side - where.y
    c, s = np.cos(where.yaw), np.sin(where.yaw)
    col = np.floor((c * dx[None, :] + s * dy[:, None]) / side).astype(np.int64)  # turned back
    row = np.floor((c * dy[:, None] - s * dx[None, :]) / side).astype(np.int64)
    inside = (col >= 0) & (col < width) & (row >= 0) & (row < height)
    out[r0:r1, c0:c1][inside] = cells[row[inside], col[inside]]


def nav2_pixels(cells: Cells) -> npt.NDArray[np.uint8]:
    """nav2's trinary picture of occupancy (row 0 the top, as a PGM's): at least
    65 occupied (0), 0 to 24 free (254), else or unknown (-1) 205: the shares
    `mapctl grid` casts scans with, as percentages."""
    pixels = np.full(cells.shape, UNKNOWN, dtype=np.uint8)
    pixels[cells >= round(OCCUPIED_P * 100)] = OCCUPIED
    pixels[(cells >= 0) & (cells < round(FREE_P * 100))] = FREE
    return pixels[::-1]
