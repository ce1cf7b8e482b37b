"""The map operations of `mapctl` (export, missions, plot, loading by box; import
is `import_ops`'s),
JSON in and out.

`MapOperations` is one of the operation sets of `mapapi.service.ops.Operations`
(`mapapi.app` adds it to the service's), so these run in the peer daemon when
one runs, like every other operation. File paths are the caller's; `mapctl`
sends them absolute, since the daemon's working folder is not the caller's.
Reading and writing files and reading missions from the store run in worker
threads (`mapapi.maps.stored`), and pictures are drawn in a process of their
own (`mapapi.service.processes`), so the peer keeps serving (heartbeats, and
`import_progress`) meanwhile (issue 14 §1). The readers, which need numpy, are
imported when first used: every `mapctl` command imports this.

`load_bbox` makes "load what lies in this box" one operation, so the CLI and
`mapctl demo` share it: participate in every chunk found that is not held
here, then in the chunks of each mission found that the box needs: the
spatial tiles of its graph that overlap the box (`mapapi.maps.tiles`), each
with its vertices and its edges. Edges have no position, so the spatial index
never lists their chunks; the mission's row names them (`Mission.tiles`), and
it is read once the row's chunk is here.
`load_progress` answers how far a running `load_bbox` got.
"""

from __future__ import annotations

import asyncio
import json
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any, TypeVar

from mapapi.core.errors import RequestTimeout
from mapapi.core.ids import ChunkId, PeerId
from mapapi.lookup.spatial import BBox
from mapapi.maps.grid_ops import GridOperations
from mapapi.maps.import_ops import ImportOperations
from mapapi.maps.op_parts import absolute, box_json, tile_json
from mapapi.maps.schema import CLOUDS, FRAMES, MISSIONS
from mapapi.service.ops import Operation
from mapapi.service.transfer_ops import online, placed_json

if TYPE_CHECKING:
    from mapapi.maps.stored import MissionInfo
    from mapapi.net.messages import Member
    from mapapi.service.peer import Peer

Json = Any
T = TypeVar("T")

LOAD_PARALLEL = 4
"""Chunks `load_bbox` joins at once."""
JOIN_ATTEMPTS = 3
"""Times `load_bbox` asks for a chunk whose state is late (each waits `PROPOSE_TIMEOUT`)."""


def member_json(member: Member) -> Json:
    """A holder: its id, name and address."""
    return {"id": member.id, "name": member.name, "address": member.address}


def _load_key(bbox: list[float], table: str | None) -> str:
    return json.dumps([list(bbox), table])


class MapOperations:
    """Map operations over one peer (see the module docstring)."""

    def __init__(self, peer: Peer, grids: GridOperations | None = None) -> None:
        self.peer = peer
        self.imports = ImportOperations(peer)
        self.grids = grids or GridOperations(peer)  # writes `export`'s nav2 maps
        self._loads: dict[str, tuple[int, int]] = {}  # load key -> (loaded, to load so far)

    def operations(self) -> Mapping[str, Operation]:
        """See `mapapi.service.ops.OperationSet`."""
        return {
            **self.imports.operations(),
            "export_map": self.export_map,
            "missions": self.missions,
            "plot_map": self.plot_map,
            "load_bbox": self.load_bbox,
            "load_progress": self.load_progress,
        }

    async def export_map(
        self, mission: str, path: str, fmt: str | None = None, frame: str = "mission"
    ) -> Json:
        """Write a mission to a file in `fmt`, by default the one the extension
        names (`mapapi.maps.jobs.export_mission`: a graph as g2o, its poses as TUM
        or KITTI, a cloud as PLY or PCD, a ROS 2 bag; a nav2 map through
        `GridOperations.export_grid`); a graph's poses in `frame`."""
        from mapapi.maps.jobs import GRID, export_format, export_mission, export_reads
        from mapapi.maps.stored import read_time

        target = absolute(path)
        fmt = export_format(target, fmt)
        if fmt == GRID:
            return await self.grids.export_grid(mission, str(target), frame)
        async with read_time(self.peer, [mission], export_reads(fmt, frame)) as at:
            counts = await self._job(export_mission, at, mission, target, fmt, frame)
        return {"mission": mission, "path": str(target), "format": fmt, "frame": frame, **counts}

    async def missions(self, swarm: bool = False, frame: str = "mission") -> Json:
        """The missions held here with their counts, box and holders; with
        `swarm`, also those the spatial index lists on other peers (counts None).
        In the world `frame`, each held one says whether it is aligned, and its
        box is there (None if not)."""
        from mapapi.maps.frames import frame_reads, world_box, world_places
        from mapapi.maps.stored import list_missions

        frame_reads(frame)  # refuses an unknown frame
        peer = online(self.peer) if swarm else self.peer
        held = await list_missions(peer)
        rows = [self._mission_json(info) for info in held]
        if frame != "mission":
            places = await world_places(peer, [info.name for info in held])
            for row, info in zip(rows, held, strict=True):
                place = places[info.name]
                box = (
                    None if place is None or info.bbox is None else world_box(info.bbox, place.pose)
                )
                row.update(frame=frame, aligned=place is not None, bbox=box_json(box))
        if swarm:
            names = {info.name for info in held}
            for found in await peer.query_bbox(peer.grid.bounds, MISSIONS):
                for name in found.ref.missions:
                    if name not in names and not found.held:
                        holders = [self._holder(m.id, m.address) for m in found.holders]
                        rows.append(_remote_json(name, found.ref.bbox, holders))
                        names.add(name)
        return {"missions": sorted(rows, key=lambda r: r["name"])}

    def _mission_json(self, info: MissionInfo) -> Json:
        return {
            "name": info.name,
            "robot": info.robot,
            "kind": info.kind,
            "vertices": info.vertices,
            "edges": info.edges,
            "landmarks": info.landmarks,
            "points": info.points,
            "bbox": box_json(info.bbox),
            "chunks": dict(info.chunks),
            "tiles": [tile_json(t) for t in info.tiles],
            "holders": [self._holder(p) for p in info.holders],
            "held": True,
        }

    def _holder(self, peer_id: PeerId, address: str = "") -> Json:
        """A holder by id, named (and addressed) as this peer knows it."""
        peer = self.peer
        if peer_id == peer.id:
            address = peer.address if peer.swarm is not None else ""
            return {"id": peer.id, "name": peer.name, "address": address}
        known = {s.member.id: s.member for s in peer.members()} if peer.swarm is not None else {}
        member = known.get(peer_id)
        return member_json(member) if member else {"id": peer_id, "name": "", "address": address}

    async def _job(self, job: Callable[..., T], *args: Any) -> T:
        """Run a long map job (`mapapi.maps.jobs.run_job`) off the event loop."""
        from mapapi.maps.jobs import run_job

        return await run_job(self.peer, job, *args)

    async def plot_map(
        self,
        path: str,
        bbox: list[float] | None = None,
        missions: list[str] | None = None,
        up: str = "auto",
        zoom: bool = False,
        title: str | None = None,
        labels: dict[str, str] | None = None,
        frame: str = "mission",
    ) -> Json:
        """Draw a top-down PNG of the missions named or matching a pattern
        (default: every mission held here, or those overlapping `bbox`), with
        `bbox` outlined; `zoom` shows the box and its surroundings only;
        `labels` maps a mission's name to its legend entry; the graphs' poses are
        in `frame` ("world" once aligned)."""
        from mapapi.maps.frames import frame_reads
        from mapapi.maps.jobs import draw_missions
        from mapapi.maps.stored import choose_missions, list_missions, read_time

        box = None if bbox is None else BBox.from_tuple(bbox)
        chosen = [
            (i.name, i.kind) for i in choose_missions(await list_missions(self.peer), missions, box)
        ]
        target = absolute(path)
        reads = (*frame_reads(frame), CLOUDS)
        async with read_time(self.peer, [name for name, _ in chosen], reads) as at:
            drawn = await self._job(
                draw_missions, at, chosen, target, box, up, zoom, title, labels, frame
            )
        return {
            "path": str(target),
            "renderer": drawn.renderer,
            "up": drawn.up,
            "missions": drawn.missions,
            "bbox": box_json(box),
            "frame": frame,
        }

    async def load_bbox(
        self, bbox: list[float], table: str | None = None, frame: str = "mission"
    ) -> Json:
        """Participate in every chunk in `bbox` (of `table`) not held here, and in
        the chunks of the missions found that the box needs: their tiles that
        overlap it (`MissionParts.in_box`). Returns the query's results afterwards
        (every chunk now held), `loaded`: each chunk fetched, in order, with its
        rows and their bytes, and `items` and `bytes`: what was fetched in all.
        In the world `frame`, the box is in the world frame: it finds the aligned
        missions' places there, then loads their rows and the tiles whose box,
        moved to the world, overlaps it (`frames.needed`).

        Raises:
            PeerNotRunning: a chunk must be fetched but the peer is off the network.
        """
        from mapapi.maps.frames import needed, row_chunks, world_places
        from mapapi.maps.stored import mission_parts

        key = _load_key(bbox, table)
        box = BBox.from_tuple(bbox)
        found = await self._query(bbox, table, frame)
        todo = [ChunkId(r["chunk"]) for r in found if not r["held"]]
        loaded: list[Json] = []
        self._loads[key] = (0, len(todo))
        try:
            loaded += await self._load_all(key, todo, todo)
            names = sorted({name for r in found for name in r["missions"]})
            places = await world_places(self.peer, names) if frame != "mission" else {}
            more = sorted(row_chunks(places) - set(self.peer.store.chunk_ids()))
            todo += more
            loaded += await self._load_all(key, more, todo)  # the rows name the tiles
            parts = await mission_parts(self.peer, names)
            wanted = needed(parts, places, box, {ChunkId(r["chunk"]) for r in found})
            more = sorted(wanted - set(self.peer.store.chunk_ids()))
            todo += more
            loaded += await self._load_all(key, more, todo)
        finally:
            self._loads.pop(key, None)
        results = await self._query(bbox, table, frame) if loaded else found
        return {
            "results": results,
            "loaded": loaded,
            "items": sum(c["items"] for c in loaded),
            "bytes": sum(c["bytes"] for c in loaded),
        }

    async def _query(self, bbox: list[float], table: str | None, frame: str) -> list[Json]:
        """The chunks in the box: in the world frame, the aligned missions' places
        (their frames chunks lie at the missions' world boxes); else those of the
        missions' own frames, which places are not."""
        if frame != "mission":
            found = await self.peer.query_bbox(BBox.from_tuple(bbox), FRAMES)
        else:
            found = await self.peer.query_bbox(BBox.from_tuple(bbox), table)
            found = [f for f in found if f.ref.table != FRAMES or table == FRAMES]
        return [placed_json(f) for f in found]

    async def _load_all(self, key: str, chunks: list[ChunkId], todo: list[ChunkId]) -> list[Json]:
        """Participate in `chunks`, `LOAD_PARALLEL` at a time (each join is a few
        round trips and a snapshot: one after another, a mission's tiles took
        seconds); what each moved, in the order of `chunks`."""
        gate = asyncio.Semaphore(LOAD_PARALLEL)

        async def one(chunk: ChunkId) -> Json:
            async with gate:
                return await self._load(key, chunk, todo)

        try:
            async with asyncio.TaskGroup() as group:  # a failed join cancels the others
                tasks = [group.create_task(one(chunk)) for chunk in chunks]
        except ExceptionGroup as failed:  # the caller sees the error itself (its exit code)
            raise failed.exceptions[0] from None
        return [task.result() for task in tasks]

    async def _load(self, key: str, chunk: ChunkId, todo: list[ChunkId]) -> Json:
        peer = online(self.peer)
        for attempt in range(1, JOIN_ATTEMPTS + 1):
            try:
                table = await peer.participate(chunk)
                break
            except RequestTimeout:  # taken in, its state late: asking again waits for it
                if attempt == JOIN_ATTEMPTS:
                    raise
        done, _ = self._loads.get(key, (0, 0))
        self._loads[key] = (done + 1, len(todo))
        counted = await peer.off_loop(peer.store.chunks, None, chunk)  # that chunk's rows only
        items, size = (counted[0].items, counted[0].bytes) if counted else (0, 0)
        return {"chunk": chunk, "table": table, "items": items, "bytes": size}

    async def load_progress(self, bbox: list[float], table: str | None = None) -> Json:
        """How far a running `load_bbox(bbox, table)` got: chunks loaded of the
        chunks known to load so far (0 of 0 before the query answers, or when
        none runs)."""
        done, total = self._loads.get(_load_key(bbox, table), (0, 0))
        return {"loaded": done, "of": total}


def _remote_json(name: str, box: BBox, holders: list[Json]) -> Json:
    return {
        "name": name,
        "robot": None,
        "kind": None,
        "vertices": None,
        "edges": None,
        "landmarks": None,
        "points": None,
        "bbox": box_json(box),
        "chunks": {},
        "tiles": [],
        "holders": holders,
        "held": False,
    }
