"""Persisting each group's `Ready` without ever waiting on the event loop for
SQLite's write lock (issue 14 §1; etcd-io/raft's asynchronous storage writes
are the model).

A Ready must be on disk before its messages leave (a vote or an append
acknowledged and then forgotten in a crash breaks Raft). Most Readies are a
few rows, written on the loop in well under a millisecond. But SQLite has one
writer at a time, and a worker thread may hold the lock for a long while: a
snapshot of 20,000 rows being installed, a big entry applied. A write on the
loop then waited for it, 30-60 ms measured in the stall benchmark, and every
heartbeat of the peer waited too.

So the loop tries first without waiting (`store.offload.without_waiting`).
When the lock is taken, or the Ready is big (a snapshot of megabytes received,
an imported mission's entry), the Ready goes to a worker thread, which waits there,
and the group takes no new Ready until that write is done; its node keeps
stepping messages and ticks meanwhile (what it then sends waits for the next
Ready, so nothing leaves before the state it depends on is on disk). The
simulator runs the same contract with writes that end later (`mapbench.sim`,
`slow_disk`) and checks Raft's safety properties across crashes in between.

A group's members, which the store's holders of its chunk follow, are recorded
the same way (the stall benchmark caught the loop waiting 130 ms for the lock
there): on the loop when the lock is free, else by a worker, which writes the
newest members known when it gets to them.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable

from mapapi.core.ids import ChunkId, PeerId
from mapapi.store.base import ReplicaStore
from mapapi.store.offload import WriteBusy, off_loop, without_waiting
from mapapi.swarm.group_apply import HEAVY_BYTES
from mapapi.swarm.group_state import GroupState, persist, record_holders
from mapapi.swarm.raft_types import Ready

log = logging.getLogger(__name__)

SavedFn = Callable[[GroupState, Ready], None]
"""Called on the loop once a Ready handed to a worker is on disk."""
FailedFn = Callable[[GroupState, Exception], object]
"""Called on the loop when a worker's write of a Ready failed (the group halts)."""


class ReadyDisk:
    """Writes groups' Readies: on the loop when the lock is free, else in a worker.

    Args:
        store: where the groups persist.
        on_saved: continues a group's Ready loop once its deferred write is done.
        on_failed: halts a group whose deferred write failed.
    """

    def __init__(self, store: ReplicaStore, on_saved: SavedFn, on_failed: FailedFn) -> None:
        self._store = store
        self._on_saved = on_saved
        self._on_failed = on_failed
        self._writing: dict[ChunkId, asyncio.Task[None]] = {}
        self._holders: dict[ChunkId, list[PeerId]] = {}  # the newest, for a worker to write
        self._recording: dict[ChunkId, asyncio.Task[None]] = {}

    def busy(self, chunk: ChunkId) -> bool:
        """Whether a Ready of the chunk's group is being written in a worker."""
        return chunk in self._writing

    def save(self, group: GroupState, rd: Ready) -> bool:
        """Persist `rd` now if the store's write lock is free (True: go on with
        it); else start writing it in a worker and return False (`on_saved`
        follows). Raises what the store raises on the loop (the caller halts)."""
        try:
            if _heavy(rd):
                raise WriteBusy("a big write")
            with without_waiting(self._store):
                persist(self._store, group.chunk, rd)
        except WriteBusy:
            task = asyncio.get_running_loop().create_task(
                self._later(group, rd), name=f"persist {group.chunk.short}"
            )
            self._writing[group.chunk] = task
            return False
        return True

    async def _later(self, group: GroupState, rd: Ready) -> None:
        try:
            await off_loop(self._store, persist, self._store, group.chunk, rd)
        except asyncio.CancelledError:
            raise
        except Exception as exc:
            self._writing.pop(group.chunk, None)
            self._on_failed(group, exc)
            return
        self._writing.pop(group.chunk, None)
        self._on_saved(group, rd)

    def holders(self, chunk: ChunkId, peers: list[PeerId]) -> None:
        """Record `peers` as the chunk's holders: now if the store's write lock is
        free, else in a worker (see the module docstring)."""
        if chunk in self._recording:  # the worker writes these next
            self._holders[chunk] = peers
            return
        try:
            with without_waiting(self._store):
                record_holders(self._store, chunk, peers)
            return
        except WriteBusy:
            self._holders[chunk] = peers
        self._recording[chunk] = asyncio.get_running_loop().create_task(
            self._record_later(chunk), name=f"holders {chunk.short}"
        )

    async def _record_later(self, chunk: ChunkId) -> None:
        try:
            while (peers := self._holders.pop(chunk, None)) is not None:
                try:
                    await off_loop(self._store, record_holders, self._store, chunk, peers)
                except Exception as exc:  # it follows the log: the next change writes it again
                    log.warning("chunk %s: holders not recorded: %s", chunk.short, exc)
        finally:
            self._recording.pop(chunk, None)

    def then(self, chunk: ChunkId, action: Callable[[], None]) -> None:
        """Run `action` on the loop once the chunk's writes under way end (now if none):
        forgetting a group must not race a worker writing its last Ready or members."""
        self._holders.pop(chunk, None)  # members of a group being forgotten: not recorded
        tasks = [t for t in (self._writing.pop(chunk, None), self._recording.get(chunk)) if t]
        if tasks:
            asyncio.gather(*tasks, return_exceptions=True).add_done_callback(lambda _: action())
        else:
            action()

    async def close(self) -> None:
        """Stop following the writes under way: each completes in its thread (the
        store's `close` waits for it), and its Ready is not handled further."""
        tasks = [*self._writing.values(), *self._recording.values()]
        self._writing.clear()
        self._holders.clear()
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)


def _heavy(rd: Ready) -> bool:
    """Whether writing `rd` takes long enough to be a worker's job in any case."""
    return rd.snapshot is not None or sum(len(e.data) for e in rd.entries) >= HEAVY_BYTES
