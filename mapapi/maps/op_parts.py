"""What the map operation sets (`operations`, `import_ops`) share: a caller's
path, and boxes and tiles as JSON."""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from mapapi.lookup.spatial import BBox
    from mapapi.maps.tiles import TileChunks

Json = Any


def absolute(path: str) -> Path:
    """`path` from the caller's folder (the CLI sends absolute paths, since the
    daemon's working folder is not the caller's)."""
    return Path(os.path.abspath(os.path.expanduser(path)))


def box_json(box: BBox | None) -> list[float] | None:
    """A box as JSON: its six numbers, or null."""
    return None if box is None else list(box.as_tuple())


def tile_json(tile: TileChunks) -> Json:
    """One spatial tile of a mission: its box, chunks and counts."""
    return {
        "bbox": box_json(tile.bbox),
        "vertices": tile.vertices,
        "edges": tile.edges,
        "vertex_count": tile.vertex_count,
        "edge_count": tile.edge_count,
    }
