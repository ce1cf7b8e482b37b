"""The application layer: missions, pose graphs, point clouds, their import and export
(DESIGN §2).

Parsers (`g2o`, `kimera`, `cloud_file`) stream their input and never touch a
peer; `import_missions` writes parsed missions into a `Peer`, one commit each;
`stored` reads them back. Importing this package registers the map message
types (`mapapi.v1.Mission`, ...) for tables. What needs numpy (clouds, and the
import and read-back that handle them) is loaded on first use, so `mapctl`
commands that never touch a map start without it; open3d (point-cloud files),
matplotlib (plots) and gtsam (`register_missions`) are imported only when used.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from mapapi.maps.errors import MapImportError
from mapapi.maps.g2o import parse_g2o, read_g2o, write_g2o
from mapapi.maps.graph import EdgeKind, GraphEdge, MissionGraph, VertexKey, chain_odometry
from mapapi.maps.kimera import KimeraReader, read_kimera
from mapapi.maps.schema import CLOUDS, EDGES, FRAMES, LANDMARKS, MISSIONS, VERTICES

if TYPE_CHECKING:
    from mapapi.maps.cloud import PointCloud
    from mapapi.maps.importer import (
        ImportResult,
        ensure_tables,
        import_cloud,
        import_graph,
        import_graphs,
        import_missions,
    )
    from mapapi.maps.registration import Registration, linked_missions, register_missions
    from mapapi.maps.rows import build_rows
    from mapapi.maps.stored import MissionInfo, list_missions, load_cloud, load_graph

_LAZY = {
    "PointCloud": "mapapi.maps.cloud",
    "build_rows": "mapapi.maps.rows",
    **dict.fromkeys(
        (
            "ImportResult",
            "ensure_tables",
            "import_cloud",
            "import_graph",
            "import_graphs",
            "import_missions",
        ),
        "mapapi.maps.importer",
    ),
    **dict.fromkeys(
        ("MissionInfo", "list_missions", "load_cloud", "load_graph"), "mapapi.maps.stored"
    ),
    **dict.fromkeys(
        ("Registration", "linked_missions", "register_missions"), "mapapi.maps.registration"
    ),
}


def __getattr__(name: str) -> Any:
    """The names that need numpy, imported on first use (PEP 562)."""
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(module), name)


__all__ = [
    "CLOUDS",
    "EDGES",
    "FRAMES",
    "LANDMARKS",
    "MISSIONS",
    "VERTICES",
    "EdgeKind",
    "GraphEdge",
    "ImportResult",
    "KimeraReader",
    "MapImportError",
    "MissionGraph",
    "MissionInfo",
    "PointCloud",
    "Registration",
    "VertexKey",
    "build_rows",
    "chain_odometry",
    "ensure_tables",
    "import_cloud",
    "import_graph",
    "import_graphs",
    "import_missions",
    "linked_missions",
    "list_missions",
    "load_cloud",
    "load_graph",
    "parse_g2o",
    "read_g2o",
    "read_kimera",
    "register_missions",
    "write_g2o",
]
