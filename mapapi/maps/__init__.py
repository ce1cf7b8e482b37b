"""The application layer: missions, pose graphs, their import and export (DESIGN §2).

Parsers (`g2o`, `kimera`) are pure and stream their input; `import_graph`
writes a parsed mission into a `Peer` in one commit. Importing this package
registers the map message types (`mapapi.v1.Mission`, ...) for tables.
"""

from mapapi.maps.errors import MapImportError
from mapapi.maps.g2o import parse_g2o, read_g2o, write_g2o
from mapapi.maps.graph import EdgeKind, GraphEdge, MissionGraph, VertexKey, chain_odometry
from mapapi.maps.importer import (
    ImportResult,
    build_rows,
    ensure_tables,
    import_graph,
    import_graphs,
    load_graph,
)
from mapapi.maps.kimera import KimeraReader, read_kimera
from mapapi.maps.schema import CLOUDS, EDGES, LANDMARKS, MISSIONS, VERTICES

__all__ = [
    "CLOUDS",
    "EDGES",
    "LANDMARKS",
    "MISSIONS",
    "VERTICES",
    "EdgeKind",
    "GraphEdge",
    "ImportResult",
    "KimeraReader",
    "MapImportError",
    "MissionGraph",
    "VertexKey",
    "build_rows",
    "chain_odometry",
    "ensure_tables",
    "import_graph",
    "import_graphs",
    "load_graph",
    "parse_g2o",
    "read_g2o",
    "read_kimera",
    "write_g2o",
]
