"""The swarm's operations (only while the peer daemon runs): membership,
participation, queries of the spatial index and the traffic counters; a set of
`mapapi.service.ops.Operations`.

Loading what a query finds together with whole missions (`load_bbox`) is a
map operation: `mapapi.maps.operations`.
"""

from __future__ import annotations

import os
import time
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from mapapi.core.errors import PeerNotRunning, UsageError
from mapapi.core.ids import ChunkId
from mapapi.lookup.spatial import BBox
from mapapi.service.fsck import divergence_json, rollback_text
from mapapi.service.ops import Operation, check_address, resolve_id

if TYPE_CHECKING:
    from mapapi.service.loop_lag import LoopLag
    from mapapi.service.peer import Peer, PlacedChunk

Json = Any


def online(peer: Peer) -> Peer:
    """`peer`, which must be on the network.

    Raises:
        PeerNotRunning: it is not (no daemon runs on the repository).
    """
    if peer.swarm is None:
        raise PeerNotRunning(
            "no peer runs on this repository; start it with `mapctl peer start --detach` "
            "(or `mapctl peer start` in another terminal)"
        )
    return peer


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


class SwarmOperations:
    """The peer's swarm: members, chunks it replicates, spatial queries, traffic.

    Args:
        peer: the peer.
        loop_lag: the watch over the daemon's event loop (None: not watched,
            `peer_status` reports no lag).
    """

    def __init__(self, peer: Peer, loop_lag: LoopLag | None = None) -> None:
        self.peer = peer
        self.loop_lag = loop_lag
        self._progress: dict[str, tuple[int, int]] = {}  # chunk -> (parts received, parts)

    def operations(self) -> Mapping[str, Operation]:
        """See `mapapi.service.ops.OperationSet`."""
        return {
            "peer_status": self.peer_status,
            "peers": self.peers,
            "join": self.join,
            "participate": self.participate,
            "participate_progress": self.participate_progress,
            "chunk_leave": self.chunk_leave,
            "swarm_chunks": self.swarm_chunks,
            "query_bbox": self.query_bbox,
            "traffic": self.traffic,
        }

    async def peer_status(self) -> Json:
        """This peer: id, name, the address others join through, every member; the
        chunks whose hash chain differs from another holder's, and how far the store
        fell behind its high-water mark (issue 18 §3); how late its event loop
        ran over the last minute, in ms (issue 14 §1)."""
        peer = online(self.peer)
        assert peer.swarm is not None
        members = [
            {"id": m.id, "address": m.address, "name": m.name} for m in peer.swarm.members.all()
        ]
        return {
            "id": peer.id,
            "name": peer.name,
            "address": peer.address,
            "join": peer.address,
            "pid": os.getpid(),
            "members": members,
            "chunks": len(peer.store.chunk_ids()),
            "diverged": [divergence_json(d) for d in peer.store.divergences()],
            "rollback": [rollback_text(r) for r in peer.store.rollbacks()],
            "loop_lag_ms": None if self.loop_lag is None else self.loop_lag.summary().as_json(),
        }

    async def peers(self) -> Json:
        """The other members: id, address, name, seconds since last heard of
        (None: never heard from directly) and the chunks both peers hold."""
        peer = online(self.peer)
        now = time.monotonic()
        held = peer.store.chunk_ids()
        rows = []
        for state in peer.members():
            member = state.member
            seen = state.last_seen
            rows.append(
                {
                    "id": member.id,
                    "address": member.address,
                    "name": member.name,
                    "last_seen": None if seen is None else round(now - seen, 3),
                    "shared_chunks": [c for c in held if member.id in peer.store.holders(c)],
                }
            )
        return {"peers": rows}

    async def join(self, address: str) -> Json:
        """Join the swarm through the member listening at `address`."""
        peer = online(self.peer)
        members = await peer.join(check_address(address))
        return {
            "joined": address,
            "members": [{"id": m.id, "address": m.address, "name": m.name} for m in members],
        }

    async def participate(self, chunk: str) -> Json:
        """Replicate a chunk here, with its history, from any holder."""
        peer = online(self.peer)
        try:
            chunk_id = ChunkId(resolve_id(peer, "chunk", chunk))
        except UsageError as exc:
            raise UsageError(
                f"{exc}; a chunk this peer does not hold needs its full 32-digit id "
                "(`mapctl chunk list` on a peer that holds it)"
            ) from None

        def report(received: int, parts: int) -> None:
            self._progress[chunk] = (received, parts)

        self._progress[chunk] = (0, 0)
        try:
            table = await peer.participate(chunk_id, report, again=True)
        finally:
            self._progress.pop(chunk, None)
        held = await peer.off_loop(peer.store.chunks, None, chunk_id)
        items = held[0].items if held else 0
        return {
            "chunk": chunk_id,
            "table": table,
            "items": items,
            "holders": peer.holders(chunk_id),
        }

    async def participate_progress(self, chunk: str) -> Json:
        """How far a running `participate(chunk)` got: parts received of all parts
        (0 of 0 before the first part, or when none runs)."""
        received, parts = self._progress.get(chunk, (0, 0))
        return {"chunk": chunk, "received": received, "parts": parts}

    async def chunk_leave(self, chunk: str, force: bool = False) -> Json:
        """Stop replicating a chunk (the last holder needs `force`)."""
        peer = online(self.peer)
        chunk_id = ChunkId(resolve_id(peer, "chunk", chunk))
        peer.chunk_table(chunk_id)  # NotParticipatingError if it is not held here
        await peer.leave_chunk(chunk_id, force=force)
        return {"chunk": chunk_id, "left": True}

    async def swarm_chunks(self) -> Json:
        """Every chunk a member of the swarm (this peer included) holds."""
        from mapapi.service.control import ask_chunk_lists

        peer = online(self.peer)
        found: dict[str, Json] = {
            c.id: {"id": c.id, "table": c.table, "holders": [peer.id]}
            for c in await peer.off_loop(peer.chunks)
        }
        for member, chunks in (await ask_chunk_lists(peer)).items():
            for c in chunks:
                entry = found.setdefault(c.chunk, {"id": c.chunk, "table": c.table, "holders": []})
                entry["holders"].append(member)
        return {"chunks": [found[k] for k in sorted(found)]}

    async def query_bbox(self, bbox: list[float], table: str | None = None) -> Json:
        """The chunks (and the missions they hold) whose box overlaps `bbox`
        (xmin, ymin, zmin, xmax, ymax, zmax), with their holders."""
        box = BBox.from_tuple(bbox)
        return {"results": [placed_json(f) for f in await self.peer.query_bbox(box, table)]}

    async def traffic(self) -> Json:
        """What this peer's swarm transport moved since it started: messages and
        bytes sent and received (in total and by message type) and dropped."""
        peer = online(self.peer)
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
