"""The operations behind `mapctl watch` (DESIGN §8): a remote subscription held
by the running peer, drained by the command in long polls.

`watch_start` subscribes and returns a watch id; `watch_next` waits up to its
timeout for changes and returns every change queued by then (one entry per
pushed revision, in commit order); `watch_stop` cancels. A watch nobody has
polled for `ABANDONED_S` seconds (its command was killed) is cancelled the next
time any watch operation runs, so a daemon never pushes forever to no one.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from mapapi.core.errors import UsageError
from mapapi.core.table import TableDescriptor
from mapapi.lookup.spatial import BBox
from mapapi.service.ops import Operation
from mapapi.service.transfer_ops import online
from mapapi.swarm.subscriptions import Subscription, SubscriptionSpec, parse_where

if TYPE_CHECKING:
    from mapapi.service.peer import Peer
    from mapapi.swarm.triggers import CommitEvent

Json = Any

ABANDONED_S = 60.0
"""Seconds after its last poll that a watch counts as abandoned."""

_MAX_WAIT_S = 30.0  # one long poll; the command polls again


class WatchOperations:
    """The `watch_*` operations over one peer; a set of `mapapi.service.ops.Operations`."""

    def __init__(self, peer: Peer) -> None:
        self.peer = peer
        self._watches: dict[str, tuple[Subscription, float]] = {}  # id -> (it, last poll)

    def operations(self) -> Mapping[str, Operation]:
        """See `mapapi.service.ops.OperationSet`."""
        return {
            "watch_start": self.watch_start,
            "watch_next": self.watch_next,
            "watch_stop": self.watch_stop,
        }

    async def watch_start(
        self,
        bbox: list[float] | None = None,
        table: str | None = None,
        where: list[str] | None = None,
    ) -> Json:
        """Subscribe to changes in `bbox` (default: the whole index), of `table`,
        whose fields match every ``FIELD=VALUE`` of `where`."""
        peer = online(self.peer)
        await self._sweep()
        region = peer.grid.bounds if bbox is None else BBox.from_tuple(bbox)
        if peer.grid.clamp(region) is None:
            raise UsageError(
                f"the box lies outside the spatial index ({peer.grid.describe()}); "
                "nothing there can ever change"
            )
        spec = SubscriptionSpec(region, table, tuple(parse_where(w) for w in where or []))
        subscription = await peer.subscribe(spec)
        watch = subscription.id.hex()
        self._watches[watch] = (subscription, time.monotonic())
        return {"watch": watch, "bbox": list(region.as_tuple())}

    async def watch_next(self, watch: str, timeout: float = 1.0) -> Json:  # noqa: ASYNC109
        """The changes that arrived for `watch`, waiting up to `timeout` seconds
        for the first one (an empty list when none came)."""
        subscription = self._watch(watch)
        events: list[CommitEvent] = []
        try:
            async with asyncio.timeout(min(max(timeout, 0.0), _MAX_WAIT_S)):
                events.append(await subscription.next())
        except TimeoutError:
            pass
        while not subscription.events.empty():
            events.append(subscription.events.get_nowait())
        self._watches[watch] = (subscription, time.monotonic())
        return {"changes": [c for e in events for c in self._changes(e)]}

    async def watch_stop(self, watch: str) -> Json:
        """Cancel a watch."""
        subscription = self._watch(watch)
        del self._watches[watch]
        await self.peer.unsubscribe(subscription)
        return {"watch": watch, "stopped": True}

    def _watch(self, watch: str) -> Subscription:
        found = self._watches.get(watch)
        if found is None:
            raise UsageError(f"no watch {watch!r} on this peer (it stopped, or was abandoned)")
        return found[0]

    async def _sweep(self) -> None:
        now = time.monotonic()
        for watch, (subscription, polled) in list(self._watches.items()):
            if now - polled > ABANDONED_S:
                del self._watches[watch]
                await self.peer.unsubscribe(subscription)

    def _changes(self, event: CommitEvent) -> list[Json]:
        record = event.record
        rows = []
        for revision in event.revisions:
            type_name = event.types.get(revision.table) or self.peer.store.tables()[revision.table]
            descriptor = TableDescriptor.named(revision.table, type_name)
            rows.append(
                {
                    "commit": record.id,
                    "time": record.time,
                    "author": record.author,
                    "message": record.message,
                    "table": revision.table,
                    "chunk": revision.chunk_id,
                    "id": revision.item_id,
                    "kind": revision.kind,
                    "data": None if revision.removed else descriptor.data_to_dict(revision.data),
                }
            )
        return rows
