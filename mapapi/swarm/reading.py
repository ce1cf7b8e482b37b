"""Reading a peer's map in a swarm: a chunk not held here is fetched first (its
holders found by asking the members), and a read of a chunk at a time first
makes the replica final up to that time (`FinalReads.read_at`: caught up with the
chunk's leader, and no later commit stamped at or before it; DESIGN §13).
Alone (no swarm), reads go straight to the store.

Reads by label (a mission's rows, `mapapi.store.labels`) use the store's label
index when it keeps one, and filter the table's rows otherwise.
"""

from __future__ import annotations

import asyncio
from collections.abc import Sequence
from typing import TYPE_CHECKING

from mapapi.core.errors import ChunkNotFound, MapError
from mapapi.store.labels import LabelledStore, summarise
from mapapi.store.offload import off_loop

if TYPE_CHECKING:
    from mapapi.core.history import Revision
    from mapapi.core.ids import ChunkId, ItemId
    from mapapi.store.base import ReplicaStore
    from mapapi.store.labels import LabelFn, Labels, LabelSummary
    from mapapi.swarm.node import Swarm


async def read(
    store: ReplicaStore, swarm: Swarm | None, item_id: ItemId, time: int
) -> Revision | None:
    """The item at `time`; in a swarm, an item of a chunk not held here is
    fetched first (its chunk is found by asking the members)."""
    if swarm is None:
        return store.read(item_id, time)
    chunk = await _item_chunk(store, swarm, item_id)
    if chunk is not None:
        await swarm.reads.read_at(chunk, time)
    return store.read(item_id, time)


async def scan(
    store: ReplicaStore, swarm: Swarm | None, time: int, table: str, chunk: ChunkId | None
) -> list[Revision]:
    """Items visible at `time` in a table or chunk (read in a worker thread); a
    chunk not held here is fetched first."""
    if swarm is not None:
        for each in await _scope_chunks(store, swarm, table, chunk):
            await swarm.reads.read_at(each, time)
    return await off_loop(store, store.scan, time, table=table, chunk=chunk)


PIN_TIMEOUT = 1.0
"""Seconds a view's blind write waits to make its chunk final (`pin`)."""


async def pin(store: ReplicaStore, swarm: Swarm | None, item_id: ItemId, time: int) -> bool:
    """Make the chunk of an item held here final up to `time`, as a read at `time`
    would (see `Workspace.pin`), waiting `PIN_TIMEOUT` at most; whether it was.
    Best effort: an edit is staged even where the chunk's voters cannot be
    reached now (a minority, a chunk held by a two-phase commit), as its commit
    is refused there anyway, and a floor made later would come too late.

    Raises:
        MapError: a failure that is not the network's or the group's (not retriable).
    """
    chunk = store.item_chunk(item_id) if swarm is not None else None
    if swarm is None or chunk is None:
        return swarm is None
    try:
        await swarm.reads.read_at(chunk, time, PIN_TIMEOUT)
    except MapError as exc:
        if not exc.retriable:
            raise
        return False
    return True


async def scan_newest(store: ReplicaStore, swarm: Swarm | None, table: str) -> list[Revision]:
    """Every item of `table` as each of its chunks holds it once caught up with
    its leader, read at that chunk's clock: every commit acknowledged to it is
    seen, and no chunk is closed with a `TimeFloor` (a write to its log), but
    the chunks are not read at one time (a listing, not a snapshot). Alone, the
    items now."""
    if swarm is None:
        return await off_loop(store, store.scan, store.clock(), table=table)
    found: list[Revision] = []
    for chunk in store.chunk_ids(table):
        time = await swarm.reads.caught_up(chunk)
        found += await off_loop(store, store.scan, time, table=table, chunk=chunk)
    return found


async def latest(
    store: ReplicaStore,
    swarm: Swarm | None,
    time: int,
    *,
    item: ItemId | None = None,
    table: str = "",
    chunk: ChunkId | None = None,
) -> int:
    """The time a view begun at `time` that has read nothing yet reads at from
    now on: the chunks its first read touches (`item`'s, else `chunk`, else
    every chunk of `table`; fetched first if not held here) are caught up with
    their leaders, and if they applied commits stamped past `time`, the view
    moves to the newest of them. That is the same as having begun once they
    were up to date, and it is how a view sees a commit acknowledged on another
    peer a moment ago, whatever the two peers' Lamport clocks (DESIGN §13,
    docs/design.md "Views"). Alone, `time`."""
    if swarm is None:
        return time
    if item is not None:
        held = await _item_chunk(store, swarm, item)
        chunks = [] if held is None else [held]
    else:
        chunks = await _scope_chunks(store, swarm, table, chunk)
    return await _caught_up(swarm, chunks, time)


async def _caught_up(swarm: Swarm, chunks: Sequence[ChunkId], time: int) -> int:
    """`time`, or the newest clock of `chunks` once caught up with their leaders."""
    for each in chunks:
        time = max(time, await swarm.reads.caught_up(each))
        await _turn()
    return time


async def _turn() -> None:
    """Let the loop run others' work between two chunks: a chunk this peer leads
    alone is caught up or floored without waiting, so a mission of hundreds of
    chunks would otherwise be done in one step of the loop, each of its reads
    there waiting for the interpreter lock while another thread computes."""
    await asyncio.sleep(0)


async def _item_chunk(store: ReplicaStore, swarm: Swarm, item_id: ItemId) -> ChunkId | None:
    """The chunk of an item, fetched first if this peer holds no replica of it
    (found by asking the members); None if no one holds it."""
    chunk = store.item_chunk(item_id)
    if chunk is not None:
        return chunk
    try:
        found = await swarm.replicator.find_holders(item=item_id)
    except ChunkNotFound:
        return None
    if found.chunk is not None:
        await swarm.replicator.participate(found.chunk)
    return store.item_chunk(item_id)


async def _scope_chunks(
    store: ReplicaStore, swarm: Swarm, table: str, chunk: ChunkId | None
) -> list[ChunkId]:
    """The chunks a scan of `table` (or of its `chunk`) reads; a chunk not held
    here is fetched first."""
    if chunk is None:
        return store.chunk_ids(table)
    if chunk not in store.chunk_ids():
        await swarm.replicator.participate(chunk)
    return [chunk]


async def scan_labelled(
    store: ReplicaStore, swarm: Swarm | None, labels: Labels, time: int, label: str, table: str
) -> list[Revision]:
    """The items of `table` labelled `label` visible at `time`: from the store's
    label index when it keeps one for `labels`, else filtered from the table's
    rows. In a swarm, the label's chunks are made final up to `time` first (as
    `scan`); the rows are read in a worker thread (`off_loop`)."""
    if swarm is not None:
        for chunk in _label_chunks(store, labels, [label], (table,)):
            await swarm.reads.read_at(chunk, time)
    return await off_loop(store, scan_labelled_now, store, labels, time, label, table)


async def labelled_readable(
    store: ReplicaStore,
    swarm: Swarm | None,
    labels: Labels,
    names: Sequence[str],
    tables: Sequence[str],
    time: int,
) -> int:
    """A time at which the rows of `tables` labelled with any of `names` read the
    same from now on, on every replica, and show every commit acknowledged to
    them before: their chunks are caught up with their leaders, and the time is
    the newest of their clocks, up to which they are made final. Then
    `scan_labelled_now` reads them at that time from any thread. Alone, or
    without such rows, `time`.

    Not a later time, such as a view's begin time: a chunk whose clock is
    behind the read time is closed with a `TimeFloor` entry, a write to its log
    for a read; the newest clock closes no chunk of a mission imported in one
    transaction (they share its time)."""
    if swarm is None:
        return time
    chunks = _label_chunks(store, labels, names, tables)
    if not chunks:
        return time
    time = await _caught_up(swarm, chunks, 0)
    for chunk in chunks:
        await swarm.reads.read_at(chunk, time)
        await _turn()
    return time


def _label_chunks(
    store: ReplicaStore, labels: Labels, names: Sequence[str], tables: Sequence[str]
) -> list[ChunkId]:
    """The chunks of `tables` holding rows labelled with one of `names` (every
    chunk of those tables when the store keeps no index of `labels`)."""
    if not _indexed(store, labels):
        return [c for table in tables for c in store.chunk_ids(table)]
    assert isinstance(store, LabelledStore)
    found = (store.label_chunks(name, table) for name in names for table in tables)
    return list(dict.fromkeys(c for chunks in found for c in chunks))


def scan_labelled_now(
    store: ReplicaStore, labels: Labels, time: int, label: str, table: str
) -> list[Revision]:
    """`scan_labelled` without making chunks final: after `labelled_readable`, in
    any thread (it touches only the store)."""
    if not _indexed(store, labels):
        fn = labels.of(store.tables().get(table, ""))
        rows = store.scan(time, table=table)
        return [r for r in rows if fn is not None and _label(fn, r.data) == label]
    assert isinstance(store, LabelledStore)
    return store.scan_labelled(time, label, table=table)


def label_summaries(
    store: ReplicaStore, labels: Labels, only: Sequence[str] | None = None
) -> list[LabelSummary]:
    """Per label (of `only`, if given) and chunk, the live rows held now: kept
    by the store when it indexes `labels`, else computed from every labelled row."""
    if _indexed(store, labels):
        assert isinstance(store, LabelledStore)
        return store.label_summaries(only)
    types = store.tables()
    rows = [
        r
        for table, type_name in types.items()
        if labels.of(type_name) is not None
        for r in store.scan(store.clock(), table=table)
    ]
    found = summarise(rows, labels, types)
    return found if only is None else [s for s in found if s.label in set(only)]


def _indexed(store: ReplicaStore, labels: Labels) -> bool:
    """Whether `store` keeps the index of `labels`."""
    return isinstance(store, LabelledStore) and store.labels.signature == labels.signature


def _label(fn: LabelFn, data: bytes) -> str | None:
    row = fn(data)
    return None if row is None else row.label
