"""A nav2 map cut into tiles (`mapapi.maps.map_tiles`): each tile a map of its
own whose origin follows from the grid's by whole cells, put back together the
grid cell for cell, all-unknown tiles left out, and an index that lists them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from mapapi.maps.grid import FREE, OCCUPIED, UNKNOWN, GridSpec
from mapapi.maps.map_tiles import index_path, tile_path, write_tiles
from tests.unit.nav2_maps import put_back


def test_tiles_put_back_together_are_the_grid(tmp_path: Path) -> None:
    rng = np.random.default_rng(7)
    spec = GridSpec(-3.25, 1.5, 0.05, 23, 17)
    pixels = rng.choice(np.array([OCCUPIED, FREE, UNKNOWN], np.uint8), size=(17, 23))
    pixels[:7, 16:] = UNKNOWN  # the top-right tile (row 2, column 2) all unknown

    tiled = write_tiles(pixels, spec, tmp_path / "big.yaml", 8)

    assert tiled.index == index_path(tmp_path / "big.yaml") == tmp_path / "big.tiles.yaml"
    assert tiled.skipped == 1
    assert [(t.row, t.col) for t in tiled.tiles] == [
        (r, c) for r in range(3) for c in range(3) if (r, c) != (2, 2)
    ]
    assert not tile_path(tmp_path / "big.yaml", 2, 2).exists()
    last = tiled.tiles[-1]  # row 2, column 1: one row of cells left at the top
    assert (last.yaml.name, last.spec.width, last.spec.height) == ("big_r2_c1.yaml", 8, 1)
    listed, whole = put_back(tiled.index)
    assert (listed["rows"], listed["columns"], listed["origin"]) == (3, 3, [-3.25, 1.5, 0.0])
    assert np.array_equal(whole, pixels)
    assert not (tmp_path / "big.yaml").exists()  # the index, not one large map


def test_a_grid_all_unknown_lists_no_tile(tmp_path: Path) -> None:
    spec = GridSpec(0.0, 0.0, 0.1, 4, 4)
    tiled = write_tiles(np.full((4, 4), UNKNOWN, np.uint8), spec, tmp_path / "m.yaml", 2)
    assert (tiled.tiles, tiled.skipped) == ([], 4)
    assert yaml.safe_load(tiled.index.read_text())["tiles"] == []
    with pytest.raises(ValueError, match="at least one cell"):
        write_tiles(np.zeros((4, 4), np.uint8), spec, tmp_path / "m.yaml", 0)
