"""Operations that find and move data between peers: `query_bbox`, `load_bbox`
(`mapctl query-bbox [--load]`) and the traffic counters.

`load_bbox` makes "load what lies in this box" one operation, so the CLI and
`mapctl demo` share it: participate in every chunk found that is not held
here, then in the other chunks of each mission found. A mission's edges have
no position, so the spatial index never lists their chunk; the mission's row
names it (`Mission.chunks`), and it is read once the row's chunk is here.
`load_progress` answers how far a running `load_bbox` got.
"""

from __future__ import annotations

import json
from functools import cached_property
from typing import TYPE_CHECKING, Any

from mapapi.core.ids import ChunkId
from mapapi.lookup.spatial import BBox

if TYPE_CHECKING:
    from mapapi.service.peer import Peer, PlacedChunk

Json = Any


def placed_json(found: PlacedChunk) -> Json:
    """One chunk a query found: its ref, table, missions, box and holders."""
    ref = found.ref
    return {
        "ref": ref.chunk,
        "kind": "mission" if ref.missions else "chunk",
        "chunk": ref.chunk,
        "table": ref.table,
        "missions": list(ref.missions),
        "bbox": list(ref.bbox.as_tuple()),
        "holders": [{"id": m.id, "name": m.name, "address": m.address} for m in found.holders],
        "held": found.held,
    }


def _key(bbox: list[float], table: str | None) -> str:
    return json.dumps([list(bbox), table])


class TransferOperations:
    """Query and load operations over `self.peer` (see the module docstring)."""

    peer: Peer

    def _on_swarm(self) -> Peer:
        """The peer, which must be on the network (Operations refines the error)."""
        raise NotImplementedError

    @cached_property
    def _loads(self) -> dict[str, tuple[int, int]]:
        """Key of a running load -> (chunks loaded, chunks to load so far)."""
        return {}

    async def query_bbox(self, bbox: list[float], table: str | None = None) -> Json:
        """The chunks (and the missions they hold) whose box overlaps `bbox`
        (xmin, ymin, zmin, xmax, ymax, zmax), with their holders."""
        box = BBox.from_tuple(bbox)
        return {"results": [placed_json(f) for f in await self.peer.query_bbox(box, table)]}

    async def load_bbox(self, bbox: list[float], table: str | None = None) -> Json:
        """Participate in every chunk in `bbox` (of `table`) not held here, and in
        the other chunks of the missions found; the query's results afterwards
        (every chunk now held) and `loaded`: each chunk fetched, in order.

        Raises:
            PeerNotRunning: a chunk must be fetched but the peer is off the network.
        """
        from mapapi.maps.stored import mission_chunks

        key = _key(bbox, table)
        found = (await self.query_bbox(bbox, table))["results"]
        todo = [ChunkId(r["chunk"]) for r in found if not r["held"]]
        loaded: list[Json] = []
        self._loads[key] = (0, len(todo))
        try:
            loaded += [await self._load(key, chunk, todo) for chunk in todo]
            names = {name for r in found for name in r["missions"]}
            held = {c.id for c in self.peer.chunks()}
            parts = await mission_chunks(self.peer, names)
            more = sorted({c for tables in parts.values() for c in tables.values()} - held)
            todo += more
            loaded += [await self._load(key, chunk, todo) for chunk in more]
        finally:
            self._loads.pop(key, None)
        results = (await self.query_bbox(bbox, table))["results"] if loaded else found
        return {"results": results, "loaded": loaded}

    async def _load(self, key: str, chunk: ChunkId, todo: list[ChunkId]) -> Json:
        peer = self._on_swarm()
        table = await peer.participate(chunk)
        self._loads[key] = (todo.index(chunk) + 1, len(todo))
        items = next((c.items for c in peer.chunks() if c.id == chunk), 0)
        return {"chunk": chunk, "table": table, "items": items}

    async def load_progress(self, bbox: list[float], table: str | None = None) -> Json:
        """How far a running `load_bbox(bbox, table)` got: chunks loaded of the
        chunks known to load so far (0 of 0 before the query answers, or when
        none runs)."""
        done, total = self._loads.get(_key(bbox, table), (0, 0))
        return {"loaded": done, "of": total}

    async def traffic(self) -> Json:
        """What this peer's swarm transport moved since it started: messages and
        bytes sent and received (in total and by message type) and dropped."""
        peer = self._on_swarm()
        assert peer.swarm is not None
        stats = peer.swarm.rpc.transport.stats

        def totals(table: dict[str, Any]) -> Json:
            return {
                "messages": sum(t.messages for t in table.values()),
                "bytes": sum(t.bytes for t in table.values()),
            }

        sent, received = stats.sent_by_type(), stats.received_by_type()
        return {
            "sent": totals(sent),
            "received": totals(received),
            "dropped": stats.dropped_count(),
            "sent_by_type": {k: t.bytes for k, t in sorted(sent.items())},
            "received_by_type": {k: t.bytes for k, t in sorted(received.items())},
        }
