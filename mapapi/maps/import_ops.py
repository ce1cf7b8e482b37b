"""`mapctl import`: read a map file into missions and commit each, as an
operation of the peer (in its daemon when one runs), and tell how far a
running import got.

The file is read in a worker thread (`read_source`, and for a laser log asked
to, the scan matching of its trajectory), so the peer keeps serving
heartbeats and `import_progress` meanwhile; the missions are then committed
one by one (`mapapi.maps.importer`).
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Mapping
from functools import partial
from typing import TYPE_CHECKING, Any

from mapapi.maps.op_parts import absolute, box_json, tile_json
from mapapi.service.ops import Operation

if TYPE_CHECKING:
    from mapapi.maps.importer import ImportResult
    from mapapi.service.peer import Peer

Json = Any


def import_json(result: ImportResult) -> Json:
    """One imported mission."""
    found: Json = {
        "name": result.mission,
        "robot": result.robot,
        "vertices": result.vertices,
        "edges": result.edges,
        "landmarks": result.landmarks,
        "points": result.points,
        "bbox": box_json(result.bbox),
        "chunks": dict(result.chunks),
        "tiles": [tile_json(t) for t in result.tiles],
        "commit": result.commit,
        "warnings": list(result.warnings),
    }
    if result.correction is not None:  # a laser log imported with --scan-match
        found["scan_match"] = {
            "keyframes": result.correction.keyframes,
            "largest": result.correction.largest,
        }
    return found


class ImportOperations:
    """The `import` operations over one peer."""

    def __init__(self, peer: Peer) -> None:
        self.peer = peer
        self._imports: dict[str, tuple[int, int]] = {}  # path -> (done, total) of an import

    def operations(self) -> Mapping[str, Operation]:
        """See `mapapi.service.ops.OperationSet`."""
        return {"import_map": self.import_map, "import_progress": self.import_progress}

    async def import_map(
        self,
        path: str,
        fmt: str | None = None,
        mission: str | None = None,
        robot: str | None = None,
        voxel: float | None = None,
        topics: list[str] | None = None,
        scan_match: bool = False,
        tf_frame: str | None = None,
    ) -> Json:
        """Import a map file or Kimera folder: parse it all (a laser log's
        trajectory scan-matched if `scan_match`), then one commit per mission;
        a malformed file commits nothing (the error names the line)."""
        from mapapi.maps.importer import import_missions
        from mapapi.maps.source import detect_format, read_source

        source = absolute(path)
        fmt = fmt or detect_format(source)

        def report(done: int, total: int) -> None:
            self._imports[path] = (done, total)

        started = time.perf_counter()
        self._imports[path] = (0, 0)
        try:
            read = partial(read_source, source, fmt, mission=mission, robot=robot, voxel=voxel)
            read = partial(read, topics=topics or (), tf_frame=tf_frame, scan_match=scan_match)
            sources = await asyncio.to_thread(read, progress=report)
            results = await import_missions(self.peer, sources, report)
        finally:
            self._imports.pop(path, None)
        seconds = time.perf_counter() - started
        elements = sum(r.elements() for r in results)
        return {
            "path": str(source),
            "format": fmt,
            "missions": [import_json(r) for r in results],
            "elements": elements,
            "points": sum(r.points for r in results),
            "seconds": round(seconds, 4),
            "elements_per_s": round(elements / seconds) if seconds > 0 else None,
        }

    async def import_progress(self, path: str) -> Json:
        """How far a running `import_map(path)` got: (done, total) of its current
        phase, total 0 while unknown (0 of 0 when none runs)."""
        done, total = self._imports.get(path, (0, 0))
        return {"path": path, "done": done, "total": total}
