"""What a chunk got since a time is read through the chunk's own time index.

The mission rules ask every held chunk, at every commit, for the revisions it got
since they last looked (`changed_since`). Through a time index over the whole
table that read every revision since of every chunk, and an import into a
repository of 10 missions took 9x as long as into an empty one. The store now
keeps a (chunk, time) index and none by table (a table's rows are its chunks');
a format-1 store gets it when it is brought to format 2 (`test_store_format.py`).
"""

from __future__ import annotations

import random
from collections.abc import Iterator
from pathlib import Path

import pytest

from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId
from mapapi.store import SqliteStore
from tests.unit.query_plans import plans_of

AUTHOR = PeerId.new()


def _fill(store: SqliteStore, rnd: random.Random, commits: int) -> list[Revision]:
    """`commits` commits to tables t and u (chunks a, b of t; c of u), at rising
    times, each to one chunk: inserts and updates of a few items."""
    chunks = {ChunkId.new(): "t", ChunkId.new(): "t", ChunkId.new(): "u"}
    for table in ("t", "u"):
        store.add_table(table, "google.protobuf.Struct")
    for chunk, table in chunks.items():
        store.add_chunk(chunk, table)
    items: dict[ChunkId, list[ItemId]] = {c: [] for c in chunks}
    written: list[Revision] = []
    for time in range(1, commits + 1):
        chunk = rnd.choice(list(chunks))
        record = CommitRecord(CommitId.new(), time, AUTHOR, "", (chunk,))
        fresh = [ItemId.new() for _ in range(rnd.randrange(3))]
        changed = set(rnd.sample(items[chunk], min(len(items[chunk]), rnd.randrange(3))))
        revisions = [
            Revision(i, chunks[chunk], chunk, b"", time, time, False, AUTHOR, record.id)
            for i in [*fresh, *changed]
        ]
        items[chunk] += fresh
        store.apply_commit(record, revisions)
        written += revisions
    return written


@pytest.fixture
def store(tmp_path: Path) -> Iterator[SqliteStore]:
    opened = SqliteStore(tmp_path / "store.sqlite", create=True)
    yield opened
    opened.close()


def test_what_a_chunk_or_a_table_got_since_a_time_is_exactly_that(store: SqliteStore) -> None:
    written = _fill(store, random.Random(7), 200)
    for since in (0, 50, 120, 199, 200):
        for chunk in store.chunk_ids():
            want = sorted((r.update_time, r.item_id) for r in written if r.chunk_id == chunk)
            got = [(r.update_time, r.item_id) for r in store.changed_since(since, chunk=chunk)]
            assert got == [w for w in want if w[0] > since]
        for table in ("t", "u"):
            want = sorted((r.update_time, r.item_id) for r in written if r.table == table)
            got = [(r.update_time, r.item_id) for r in store.changed_since(since, table=table)]
            assert got == [w for w in want if w[0] > since]


def test_a_chunk_and_a_tables_chunks_are_read_through_the_chunk_time_index(
    store: SqliteStore,
) -> None:
    _fill(store, random.Random(1), 30)
    chunk = store.chunk_ids("t")[0]
    for read in (
        lambda: store.changed_since(10, chunk=chunk),
        lambda: store.changed_since(10, table="t", chunk=chunk),
        lambda: store.changed_since(10, table="t"),
    ):
        (plan,) = plans_of(store, read)
        assert "SEARCH r USING INDEX revisions_chunk_time (chunk_no=? AND update_time>?)" in plan
        assert not any(step.startswith("SCAN r") for step in plan), plan
