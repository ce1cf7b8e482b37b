"""Reading a peer's map in a swarm: a chunk not held here is fetched first (its
holders found by asking the members), and a read of a chunk waits while a
writer holds its lock, so no commit at or before the read time can still
arrive (DESIGN §5). Alone (no swarm), reads go straight to the store.

Reads by label (a mission's rows, `mapapi.store.labels`) use the store's label
index when it keeps one, and filter the table's rows otherwise.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from mapapi.core.errors import ChunkNotFound
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
    revision = store.read(item_id, time)
    if swarm is None:
        return revision
    if revision is None and store.item_chunk(item_id) is None:
        try:
            found = await swarm.replicator.find_holders(item=item_id)
        except ChunkNotFound:
            return None
        if found.chunk is not None:
            await swarm.replicator.participate(found.chunk)
    chunk = store.item_chunk(item_id)
    if chunk is not None:
        await swarm.locks.wait_readable(chunk)
    return store.read(item_id, time)


async def scan(
    store: ReplicaStore, swarm: Swarm | None, time: int, table: str, chunk: ChunkId | None
) -> list[Revision]:
    """Items visible at `time` in a table or chunk (read in a worker thread); a
    chunk not held here is fetched first."""
    if swarm is not None:
        if chunk is not None and chunk not in {c.id for c in store.chunks()}:
            await swarm.replicator.participate(chunk)
        chunks = [chunk] if chunk is not None else [c.id for c in store.chunks(table)]
        for each in chunks:
            await swarm.locks.wait_readable(each)
    return await off_loop(store, store.scan, time, table=table, chunk=chunk)


async def scan_labelled(
    store: ReplicaStore, swarm: Swarm | None, labels: Labels, time: int, label: str, table: str
) -> list[Revision]:
    """The items of `table` labelled `label` visible at `time`: from the store's
    label index when it keeps one for `labels`, else filtered from the table's
    rows. In a swarm, a read of the label's chunks waits while a writer holds
    them (as `scan`); the rows are read in a worker thread (`off_loop`)."""
    await labelled_readable(store, swarm, labels, label, (table,))
    return await off_loop(store, scan_labelled_now, store, labels, time, label, table)


async def labelled_readable(
    store: ReplicaStore, swarm: Swarm | None, labels: Labels, label: str, tables: Sequence[str]
) -> None:
    """Wait until no writer holds a chunk of `tables` with rows labelled `label`
    (every chunk of those tables when the store keeps no index of `labels`), so
    no commit at or before a read time taken now can still arrive there."""
    if swarm is None:
        return
    for table in tables:
        if _indexed(store, labels):
            assert isinstance(store, LabelledStore)
            chunks = store.label_chunks(label, table)
        else:
            chunks = [c.id for c in store.chunks(table)]
        for chunk in chunks:
            await swarm.locks.wait_readable(chunk)


def scan_labelled_now(
    store: ReplicaStore, labels: Labels, time: int, label: str, table: str
) -> list[Revision]:
    """`scan_labelled` without waiting for writers: after `labelled_readable`, in
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
