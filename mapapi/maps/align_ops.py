"""`mapctl align`: place missions in one shared `world` frame and commit where
each lies (issue 17 §1), as an operation of the peer (in its daemon when one runs).

The computation (`mapapi.maps.world.align_world`, gtsam) runs off the event
loop, in a process of its own while the peer serves a swarm (`jobs.run_job`).
Its result is staged in a view, as `mapctl set` stages an edit, and the view
is committed: a mission's place is one row in its frames chunk
(`mapapi.maps.frames`), so an alignment committed meanwhile by another peer is
a conflict on those rows, kept in the view for `mapctl diff` and `mapctl
resolve` and committed with `mapctl commit`, like any other.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from mapapi.core.errors import UsageError
from mapapi.core.ids import ChunkId
from mapapi.maps.schema import FRAMES, MISSIONS, Frame
from mapapi.service.ops import Operation

if TYPE_CHECKING:
    from mapapi.core.transaction import Transaction
    from mapapi.maps.world import WorldAlignment, WorldFrame
    from mapapi.service.peer import Peer
    from mapapi.service.workspace import Workspace

WORLD = "world"  # mapapi.maps.world.WORLD, which needs numpy: imported when used

Json = Any


def frame_json(found: WorldFrame) -> Json:
    """One mission's place in the world frame."""
    return {
        "mission": found.mission,
        "frame": WORLD,
        "transform": [float(v) for v in found.pose],
        "covariance": list(found.covariance),
        "anchor": found.anchor,
        "linked": list(found.linked),
        "edges": found.edges,
        "duplicate_of": found.duplicate_of or None,
    }


def alignment_json(result: WorldAlignment) -> Json:
    """What an alignment found (without its commit)."""
    return {
        "frame": WORLD,
        "anchor": result.anchor,
        "frames": [frame_json(f) for f in result.frames.values()],
        "unaligned": list(result.unaligned),
        "edges": result.edges,
        "inliers": result.inliers,
        "rms_before": {"metres": result.before.metres, "degrees": result.before.degrees},
        "rms_after": {"metres": result.after.metres, "degrees": result.after.degrees},
    }


class AlignOperations:
    """The `align` operation over one peer and its views."""

    def __init__(self, peer: Peer, views: Workspace) -> None:
        self.peer = peer
        self.views = views

    def operations(self) -> Mapping[str, Operation]:
        """See `mapapi.service.ops.OperationSet`."""
        return {"align": self.align}

    async def align(
        self,
        view: str,
        missions: list[str] | None = None,
        anchor: str | None = None,
        message: str = "",
    ) -> Json:
        """Place the pose-graph missions named (default: every one held here) in
        the world frame, anchored at `anchor` (default: the best-joined), and
        commit each one's place through view `view`.

        Raises:
            UsageError: no pose-graph mission here, or a name matches none.
            ConflictError: another peer aligned a mission meanwhile (the
                conflicts stay in the view, for `resolve`).
        """
        from mapapi.maps.frames import frame_item, stage_frames
        from mapapi.maps.importer import ensure_tables
        from mapapi.maps.jobs import align_at, run_job
        from mapapi.maps.stored import GRAPH_READ, choose_missions, list_missions, read_time

        held = [i for i in await list_missions(self.peer) if i.kind == "graph"]
        if not held:
            raise UsageError("no pose-graph mission here to align; import one first")
        infos = {i.name: i for i in held}
        chosen = [i.name for i in choose_missions(held, missions, None)]
        if anchor is not None and anchor not in chosen:
            raise UsageError(f"the anchor {anchor!r} is not among the missions to align")
        async with read_time(self.peer, chosen, GRAPH_READ) as at:
            result = await run_job(self.peer, align_at, at, chosen, anchor)
        await ensure_tables(self.peer, {FRAMES: Frame})
        chunks, rows = await self._frame_chunks(view, list(result.frames))
        existing = await self._existing(view, list(result.frames))
        for item in [*rows, *(frame_item(name) for name in existing)]:
            await self.views.pin(view, item)  # rows it updates, maybe unread by the view

        def write(tx: Transaction) -> None:
            for item, row in rows.items():
                tx.update(MISSIONS, item, row)
            stage_frames(tx, result.frames.values(), infos, chunks, existing)

        self.views.stage(view, write)
        aligned = len(result.frames)
        text = (
            message or f"align {aligned} mission(s) in the world frame, anchored at {result.anchor}"
        )
        record = await self.views.commit(view, text)
        return {
            **alignment_json(result),
            "commit": None if record is None else record.id,
            "time": None if record is None else record.time,
            "message": text,
        }

    async def _frame_chunks(
        self, view: str, names: list[str]
    ) -> tuple[dict[str, ChunkId], dict[Any, Any]]:
        """Each mission's frames chunk, and the mission rows to update: a mission
        imported before missions had one gets a new chunk, named in its row."""
        reader = self.views.reader(view)
        found = await reader.items(MISSIONS)
        chunks: dict[str, ChunkId] = {}
        updated = {}
        for item, row in found.items():
            if row.name not in names:
                continue
            if FRAMES in row.chunks:
                chunks[row.name] = ChunkId(row.chunks[FRAMES])
                continue
            chunk = await self.peer.create_chunk(FRAMES)
            copy = type(row)()
            copy.CopyFrom(row)
            copy.chunks[FRAMES] = chunk
            updated[item] = copy
            chunks[row.name] = chunk
        return chunks, updated

    async def _existing(self, view: str, names: list[str]) -> list[str]:
        """The missions whose frame row the view sees already."""
        from mapapi.maps.frames import frame_item

        reader = self.views.reader(view)
        return [n for n in names if await reader.get(FRAMES, frame_item(n)) is not None]
