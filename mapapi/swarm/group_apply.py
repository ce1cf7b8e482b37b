"""Applying a chunk group's committed entries to the store in log order, off the
event loop when they are big (DESIGN §13; issue 14 §1: liveness must not depend
on what a commit costs).

The Ready loop (`swarm/groups.py`) persists, sends and steps on the loop, where
each of those is short. Applying is not always: a mission imported in one
transaction is an entry of megabytes, decoded, validated and written row by row
at every holder, and a snapshot is a chunk's whole history. While the loop did
that, the peer's heartbeats stopped and its groups' leaders were deposed.

So the Ready loop hands its committed entries and snapshots to `GroupApplier`:

- work that is small, with nothing of the group queued, is applied at once on
  the loop (most commits: a hop to a thread would cost more than the write),
  unless a worker holds SQLite's write lock: the loop never waits for it, or
  the loop has already applied `INLINE_BUDGET_S` of work since it last turned
  (a mission cut into 32 tiles is 64 small entries decided in one turn: applied
  there one after another, they held the loop for a second);
- anything else waits in the group's queue, and one task per group writes it in
  a worker thread (`store/offload.py`), in order, then answers the proposers and
  calls the applied hook on the loop.

The core counts entries as applied once they are handed over; the store's
applied index is what readers wait for (`RaftGroups.applied`, `catch_up`), and
it moves with the entries' effects in one store transaction, so a crash never
applies an entry twice. Compaction goes through the same queue: the chunk's
state is taken in a worker once every entry before it is written, so a snapshot
never claims an entry the store has not applied.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

from mapapi.core.ids import ChunkId
from mapapi.store.base import ReplicaStore
from mapapi.store.offload import WriteBusy, off_loop, without_waiting
from mapapi.swarm.chunk_state import StoreStates
from mapapi.swarm.group_state import (
    Applied,
    ApplyFn,
    GroupState,
    persist_compaction,
    snapshot_at,
)
from mapapi.swarm.raft_types import Entry, EntryKind

log = logging.getLogger(__name__)

HEAVY_BYTES = 64 * 1024
"""Entry and snapshot bytes from which work leaves the loop (about 500 map rows:
some 10 ms of decoding and writing on the 2-core machine)."""

INLINE_BUDGET_S = 0.02
"""Seconds of small work applied on the loop before the rest of what arrives in
the same turn of the loop goes to worker threads too."""

AppliedHook = Callable[[ChunkId, Applied], None]
"""Called on the loop with what each applied NORMAL entry did, in log order."""
HaltFn = Callable[[GroupState, Exception], object]
"""Stops a group whose work the store refused (`group_state.halted`)."""


@dataclass(frozen=True, slots=True)
class Work:
    """One Ready's share of applying, or a compaction (`compact_at` > 0)."""

    entries: tuple[Entry, ...] = ()
    snapshot: tuple[bytes, int] | None = None  # (data, index)
    compact_at: int = 0
    compact_head: tuple[int, bytes] = (0, b"")  # (term, configuration) at compact_at


@dataclass(frozen=True, slots=True)
class Done:
    """What a work's write did: each NORMAL entry's result, or the chunk's state."""

    results: dict[int, Applied]
    state: bytes = b""


def apply_entries(
    store: ReplicaStore, chunk: ChunkId, entries: tuple[Entry, ...], apply: ApplyFn
) -> dict[int, Applied]:
    """Apply committed entries in one store transaction, each NORMAL one with its
    applied index and the chunk's clock after it (so the next proposal of the
    same batch is stamped past it); what each did, by index. Any thread."""
    results: dict[int, Applied] = {}
    if not entries:
        return results
    with store.exclusive():
        for entry in entries:
            if entry.kind is EntryKind.NORMAL:
                results[entry.index] = applied = apply(chunk, entry)
                store.raft_applied(chunk, entry.index, applied.time)
        store.raft_applied(chunk, entries[-1].index)
    return results


class GroupApplier:
    """Every group's queue of work to apply (see the module docstring).

    Args:
        store: the replicas and the groups' applied indexes.
        states: takes and installs chunks' states (None: no snapshots here).
        apply: applies one NORMAL entry to the store (any thread).
        on_applied: told on the loop what each applied entry did.
        on_halt: stops a group whose work failed.
        on_drained: called on the loop once a group's queue is written (the
            Ready loop defers what needs the chunk installed until then).
    """

    def __init__(
        self,
        store: ReplicaStore,
        states: StoreStates | None,
        apply: ApplyFn,
        on_applied: AppliedHook | None,
        on_halt: HaltFn,
        on_drained: Callable[[GroupState], None] = lambda group: None,
    ) -> None:
        self._store = store
        self._states = states
        self._apply = apply
        self._on_applied = on_applied
        self._on_halt = on_halt
        self._on_drained = on_drained
        self._queues: dict[ChunkId, deque[Work]] = {}
        # what an entry costs to apply, in bytes decoded: its size unless told
        # better (a small decision writes every row its transaction prepared)
        self.weigh: Callable[[ChunkId, Entry], int] = lambda chunk, entry: len(entry.data)
        self._tasks: dict[ChunkId, asyncio.Task[None]] = {}
        self._inline_s = 0.0  # spent on the loop since it last turned

    def idle(self, chunk: ChunkId) -> bool:
        """Whether nothing of the chunk's group waits to be applied."""
        return chunk not in self._tasks

    def hand(
        self, group: GroupState, entries: tuple[Entry, ...], snapshot: tuple[bytes, int] | None
    ) -> None:
        """Apply a Ready's snapshot, then its committed entries: now if small and
        nothing is queued, else in the group's queue (errors halt the group)."""
        if entries or snapshot is not None:
            self._add(group, Work(entries, snapshot))

    def compact(self, group: GroupState, index: int) -> None:
        """Compact the group's log up to `index` (applied here) once the work
        before it is written; ignored while a compaction is queued."""
        queue = self._queues.get(group.chunk, ())
        if self._states is not None and not any(w.compact_at for w in queue):
            _, term, config, _ = snapshot_at(group, index, b"")
            self._add(group, Work(compact_at=index, compact_head=(term, config)))

    def forget(self, chunk: ChunkId) -> None:
        """Drop the chunk's queue (its group is gone); a write under way in a
        thread completes or fails alone (the store refuses an applied index for a
        chunk without a group)."""
        task = self._tasks.get(chunk)
        if task is not None:
            task.cancel()

    async def close(self) -> None:
        """Stop every group's queue (a write under way in a thread completes)."""
        tasks = list(self._tasks.values())
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)

    def _add(self, group: GroupState, work: Work) -> None:
        chunk = group.chunk
        inline = self._inline_s < INLINE_BUDGET_S and self.idle(chunk)
        if inline and self._light(chunk, work):  # raises: the caller halts
            started = time.perf_counter()
            try:
                with without_waiting(self._store):
                    done = self._write(chunk, work)
            except WriteBusy:
                pass  # a worker's long write holds the lock: this one waits in a worker too
            else:
                self._finish(group, work, done)
                return
            finally:
                self._spent(time.perf_counter() - started)
        self._queues.setdefault(chunk, deque()).append(work)
        if chunk not in self._tasks:
            loop = asyncio.get_running_loop()
            self._tasks[chunk] = loop.create_task(self._drain(group), name=f"apply {chunk.short}")

    def _spent(self, seconds: float) -> None:
        """Count time spent applying on the loop, until the loop turns."""
        if not self._inline_s:
            asyncio.get_running_loop().call_soon(self._turned)
        self._inline_s += seconds

    def _turned(self) -> None:
        self._inline_s = 0.0

    def _light(self, chunk: ChunkId, work: Work) -> bool:
        """Whether `work` is applied on the loop: entries that weigh little (a
        compaction or a snapshot, which rebuilds a chunk's chain, never is)."""
        if work.compact_at or work.snapshot is not None:
            return False
        return sum(self.weigh(chunk, e) for e in work.entries) < HEAVY_BYTES

    async def _drain(self, group: GroupState) -> None:
        """Write the group's queued work in a worker thread, one at a time, in order."""
        chunk = group.chunk
        queue = self._queues[chunk]
        try:
            while queue:
                done = await off_loop(self._store, self._write, chunk, queue[0])
                self._finish(group, queue.popleft(), done)
            self._on_drained(group)
        except asyncio.CancelledError:
            raise
        except Exception as exc:
            self._on_halt(group, exc)
        finally:
            self._tasks.pop(chunk, None)
            self._queues.pop(chunk, None)

    def _write(self, chunk: ChunkId, work: Work) -> Done:
        """The store's part of `work` (any thread)."""
        if work.compact_at:  # the state taken, and persisted, here
            assert self._states is not None
            data = self._states.take(chunk)
            persist_compaction(self._store, chunk, (work.compact_at, *work.compact_head, data))
            return Done({}, data)
        if work.snapshot is not None:
            if self._states is None:
                log.error("chunk %s: a snapshot arrived, and this peer cannot install one", chunk)
            else:
                self._states.install(chunk, *work.snapshot)
        return Done(apply_entries(self._store, chunk, work.entries, self._apply))

    def _finish(self, group: GroupState, work: Work, done: Done) -> None:
        """The loop's part of `work`, once written: answer and tell."""
        if work.compact_at:
            if group.node.log.snapshot.index < work.compact_at:  # no leader's came since
                group.node.compact(work.compact_at, done.state)
            group.progress.set()  # a joiner waiting for the founding snapshot goes on
            return
        group.progress.set()
        group.settle(work.entries, done.results)
        if self._on_applied is not None:
            for index in sorted(done.results):
                self._on_applied(group.chunk, done.results[index])
