"""A nav2 map cut into tiles, for areas too large for one image (issue 17 §4;
navigation2 #548 and #392 ask map_server for tiles).

`write_tiles` cuts a grid's pixels (`mapapi.maps.grid`) into squares of `side`
cells from its lower-left corner, the last row and column of tiles narrower,
and writes each as a map of its own, a PGM and YAML that nav2's `map_server`
loads alone (`write_nav2`), its origin the tile's lower-left corner: for
`NAME.yaml`, tile row `r` (counted up from the grid's bottom, as y grows) and
column `c` (left to right) is `NAME_r{r}_c{c}.yaml`. A tile all unknown is not
written: it would tell a robot nothing. The index `NAME.tiles.yaml` lists
the tiles written, with the whole grid's origin and size, so a loader can find
a tile's neighbours by row and column (a missing one is all unknown).

The tiles hold whole cells of the one grid, so their origins are the grid's
plus whole multiples of `side` cells, and put back together they are the grid
cell for cell. Pure: numpy only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from mapapi.maps.grid import UNKNOWN, GridSpec, write_nav2

Pixels = npt.NDArray[np.uint8]  # (height, width), row 0 the top, as `OccupancyCounts.image`


@dataclass(frozen=True, slots=True)
class MapTile:
    """One tile written: its place among the tiles, its files and its cells.

    Attributes:
        row: its row of tiles, 0 the bottom.
        col: its column of tiles, 0 the left.
        yaml: its nav2 YAML.
        image: its PGM.
        spec: where its cells lie (its origin, resolution and size).
    """

    row: int
    col: int
    yaml: Path
    image: Path
    spec: GridSpec


@dataclass(frozen=True, slots=True)
class TiledMap:
    """What `write_tiles` wrote: the index, the tiles, and how many tiles were
    left out for being all unknown."""

    index: Path
    tiles: list[MapTile]
    skipped: int


def index_path(yaml_path: Path) -> Path:
    """The index of the tiles of the map `yaml_path`: NAME.tiles.yaml."""
    return yaml_path.with_name(f"{yaml_path.stem}.tiles{yaml_path.suffix}")


def tile_path(yaml_path: Path, row: int, col: int) -> Path:
    """The YAML of tile (`row`, `col`) of the map `yaml_path`: NAME_r{row}_c{col}.yaml."""
    return yaml_path.with_name(f"{yaml_path.stem}_r{row}_c{col}{yaml_path.suffix}")


def write_tiles(pixels: Pixels, spec: GridSpec, yaml_path: Path, side: int) -> TiledMap:
    """Write `pixels` (the grid `spec`) as tiles of `side` x `side` cells beside
    `yaml_path`, each a nav2 map, and their index (see the module docstring).

    Raises:
        ValueError: `side` is not positive.
    """
    if side < 1:
        raise ValueError(f"a tile must be at least one cell a side, not {side}")
    tiles: list[MapTile] = []
    skipped = 0
    for row in range(math.ceil(spec.height / side)):
        bottom, top = row * side, min((row + 1) * side, spec.height)  # rows up from the bottom
        for col in range(math.ceil(spec.width / side)):
            left, right = col * side, min((col + 1) * side, spec.width)
            part = pixels[spec.height - top : spec.height - bottom, left:right]
            if np.all(part == UNKNOWN):
                skipped += 1
                continue
            corner = (spec.x0 + left * spec.resolution, spec.y0 + bottom * spec.resolution)
            sub = GridSpec(*corner, spec.resolution, right - left, top - bottom)
            target = tile_path(yaml_path, row, col)
            tiles.append(MapTile(row, col, target, write_nav2(part, sub, target), sub))
    index = index_path(yaml_path)
    index.write_text(_index_text(spec, side, tiles), encoding="utf-8")
    return TiledMap(index, tiles, skipped)


def _index_text(spec: GridSpec, side: int, tiles: list[MapTile]) -> str:
    """The index's YAML: the whole grid, then one line per tile written."""
    lines = [
        "# nav2 map tiles written by mapapi: each tile's yaml is a map_server map;",
        "# row 0 is the bottom row of tiles, column 0 the left; a tile not listed is all unknown",
        f"resolution: {spec.resolution!r}",
        f"tile: {side}",
        f"origin: [{spec.x0!r}, {spec.y0!r}, 0.0]",
        f"width: {spec.width}",
        f"height: {spec.height}",
        f"rows: {math.ceil(spec.height / side)}",
        f"columns: {math.ceil(spec.width / side)}",
        "tiles:" if tiles else "tiles: []",
    ]
    lines += [
        f"- {{row: {t.row}, col: {t.col}, yaml: {t.yaml.name}, "
        f"origin: [{t.spec.x0!r}, {t.spec.y0!r}, 0.0], "
        f"width: {t.spec.width}, height: {t.spec.height}}}"
        for t in tiles
    ]
    return "\n".join(lines) + "\n"
