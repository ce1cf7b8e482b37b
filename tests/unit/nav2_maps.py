"""Reading nav2 maps back for the grid tests: a PGM's pixels, and tiles
(`mapapi.maps.map_tiles`) put back together by their own YAML's origins."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from mapapi.maps.grid import UNKNOWN


def read_pgm(path: Path) -> np.ndarray:
    """A binary PGM's pixels (rows x columns), row 0 the top."""
    magic, _comment, size, _depth, pixels = path.read_bytes().split(b"\n", 4)
    assert magic == b"P5"
    width, height = map(int, size.split())
    return np.frombuffer(pixels, dtype=np.uint8).reshape(height, width)


def put_back(index: Path) -> tuple[dict[str, Any], np.ndarray]:
    """The index read as map_server would read YAML, and the grid its tiles make
    (unknown where no tile is listed), each tile placed by its own YAML's origin."""
    listed = yaml.safe_load(index.read_text())
    side, resolution = listed["tile"], listed["resolution"]
    x0, y0, _ = listed["origin"]
    out = np.full((listed["height"], listed["width"]), UNKNOWN, np.uint8)
    for entry in listed["tiles"]:
        own = yaml.safe_load((index.parent / entry["yaml"]).read_text())
        assert own["origin"] == entry["origin"]
        assert own["resolution"] == resolution
        col = round((own["origin"][0] - x0) / resolution)  # whole cells from the corner
        up = round((own["origin"][1] - y0) / resolution)
        assert (col, up) == (entry["col"] * side, entry["row"] * side)
        assert own["origin"][0] == pytest.approx(x0 + col * resolution, abs=1e-9)
        assert own["origin"][1] == pytest.approx(y0 + up * resolution, abs=1e-9)
        pixels = read_pgm(index.parent / own["image"])
        height, width = pixels.shape
        top = listed["height"] - up - height  # PGM rows run down from the top
        out[top : top + height, col : col + width] = pixels
    return listed, out
