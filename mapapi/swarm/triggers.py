"""Local triggers (DESIGN §8): callbacks on every commit applied to this peer.

A trigger watches one chunk, one table, or everything, and is called once per
applied commit that touched what it watches (local commits included) with the
inserted, updated and removed item ids. Commits are queued as they are
applied and one dispatcher task calls the triggers, commit after commit, in
the order the commits were applied here: never on the receive loop's
handlers, so a slow callback delays other callbacks but never the protocol.
An async callback is awaited on the peer's loop (it may use the peer: begin a
transaction, commit); a plain function runs in a worker thread. An exception
in a callback is logged and the next callback runs.
"""

from __future__ import annotations

import asyncio
import inspect
import logging
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass, field
from itertools import count

from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, ItemId

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class CommitEvent:
    """What one applied commit did to what a trigger watches.

    Attributes:
        record: the commit.
        inserted, updated, removed: the ids of the items it inserted, updated
            and removed among the watched ones, in commit order.
        revisions: the watched revisions themselves.
        types: for a pushed event, the protobuf type of each table of
            `revisions` (the subscriber may hold none of them).
    """

    record: CommitRecord
    inserted: tuple[ItemId, ...]
    updated: tuple[ItemId, ...]
    removed: tuple[ItemId, ...]
    revisions: tuple[Revision, ...]
    types: dict[str, str] = field(default_factory=dict)


Applied = tuple[CommitRecord, tuple[Revision, ...]]

Callback = Callable[[CommitEvent], Awaitable[None] | None]


@dataclass(frozen=True, slots=True)
class Trigger:
    """A registered callback and what it watches (a chunk, a table, or all)."""

    id: int
    callback: Callback
    chunk: ChunkId | None = None
    table: str | None = None

    def event(self, record: CommitRecord, revisions: Sequence[Revision]) -> CommitEvent | None:
        """The event of `record` for this trigger, or None when it touched nothing
        watched."""
        return commit_event(
            record,
            [
                r
                for r in revisions
                if (self.chunk is None or r.chunk_id == self.chunk)
                and (self.table is None or r.table == self.table)
            ],
        )


def commit_event(
    record: CommitRecord, revisions: Sequence[Revision], types: dict[str, str] | None = None
) -> CommitEvent | None:
    """The event of `record` over `revisions` (None when there are none)."""
    if not revisions:
        return None

    def ids(kind: str) -> tuple[ItemId, ...]:
        return tuple(r.item_id for r in revisions if r.kind == kind)

    inserted, updated, removed = ids("inserted"), ids("updated"), ids("removed")
    return CommitEvent(record, inserted, updated, removed, tuple(revisions), dict(types or {}))


@dataclass
class Triggers:
    """The triggers of one peer and the queue of commits they have yet to see."""

    _triggers: dict[int, Trigger] = field(default_factory=dict)
    _ids: count[int] = field(default_factory=lambda: count(1))
    _queue: asyncio.Queue[Applied] | None = None
    _dispatcher: asyncio.Task[None] | None = None
    _busy: int = 0  # commits queued or being dispatched
    _idle: asyncio.Event | None = None

    def add(
        self, callback: Callback, *, chunk: ChunkId | None = None, table: str | None = None
    ) -> int:
        """Call `callback` for every commit applied from now on that touches `chunk`
        (or `table`, or anything when both are None); returns the trigger's id."""
        trigger = Trigger(next(self._ids), callback, chunk, table)
        self._triggers[trigger.id] = trigger
        return trigger.id

    def remove(self, trigger_id: int) -> bool:
        """Stop calling a trigger; returns whether it existed. Commits queued
        already are not delivered to it."""
        return self._triggers.pop(trigger_id, None) is not None

    def applied(self, record: CommitRecord, revisions: Sequence[Revision]) -> None:
        """Queue a commit just applied to this peer's store (call in apply order)."""
        if not self._triggers:
            return
        queue = self._start()
        self._busy += 1
        assert self._idle is not None
        self._idle.clear()
        queue.put_nowait((record, tuple(revisions)))

    async def drained(self) -> None:
        """Wait until every commit queued so far has been through every trigger."""
        if self._idle is not None:
            await self._idle.wait()

    @property
    def idle(self) -> bool:
        """No commit is waiting for, or in, a callback."""
        return self._busy == 0

    def _start(self) -> asyncio.Queue[Applied]:
        if self._queue is None:
            self._queue = asyncio.Queue()
            self._idle = asyncio.Event()
            self._dispatcher = asyncio.get_running_loop().create_task(
                self._dispatch(self._queue), name="triggers"
            )
        return self._queue

    async def _dispatch(self, queue: asyncio.Queue[Applied]) -> None:
        while True:
            record, revisions = await queue.get()
            try:
                for trigger in list(self._triggers.values()):
                    event = trigger.event(record, revisions)
                    if event is not None:
                        await _call(trigger, event)
            finally:
                self._busy -= 1
                if self._busy == 0 and self._idle is not None:
                    self._idle.set()

    async def close(self) -> None:
        """Stop dispatching (commits still queued are dropped)."""
        task, self._dispatcher = self._dispatcher, None
        if task is not None:
            task.cancel()
            await asyncio.gather(task, return_exceptions=True)
        self._queue = None
        self._busy = 0
        if self._idle is not None:
            self._idle.set()
        self._idle = None


async def _call(trigger: Trigger, event: CommitEvent) -> None:
    try:
        if inspect.iscoroutinefunction(trigger.callback):
            await trigger.callback(event)
        else:
            result = await asyncio.to_thread(trigger.callback, event)
            if inspect.isawaitable(result):
                await result
    except Exception:  # a broken callback must never break the peer
        log.exception("trigger %d failed on commit %s", trigger.id, event.record.id.short)
