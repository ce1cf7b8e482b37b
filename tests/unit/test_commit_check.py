"""What a holder refuses to stage (mapapi.swarm.commit_check, DESIGN §5 and §11).

A real commit batch passes; each way a hostile or broken writer could make one
break the store (an item of another chunk, a wrong table, a stale time, a
payload of another type, ...) is refused with a UsageError naming it.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from pathlib import Path

import pytest

from mapapi._pb.mapapi.v1.types_pb2 import Counter
from mapapi.core import limits
from mapapi.core.errors import ChunkNotFound, LimitExceeded, UsageError
from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId
from mapapi.store.sqlite import SqliteStore
from mapapi.swarm.commit_check import check_batch

WRITER = PeerId.new()
TABLE = "counters"


class World:
    """A store with two chunks of counters; item `old` was written at time 5 in `a`."""

    def __init__(self, store: SqliteStore) -> None:
        self.store = store
        store.add_table(TABLE, "mapapi.v1.Counter")
        store.add_table("other", "google.protobuf.Struct")
        self.a, self.b, self.c = ChunkId.new(), ChunkId.new(), ChunkId.new()
        store.add_chunk(self.a, TABLE)
        store.add_chunk(self.b, TABLE)
        store.add_chunk(self.c, "other")
        self.old = ItemId.new()
        first = CommitRecord(CommitId.new(), 5, WRITER, "", (self.a,))
        store.apply_commit(
            first, [self.revision(first, self.old, Counter(value=1).SerializeToString())]
        )
        self.other = ItemId.new()  # an item of chunk b
        second = CommitRecord(CommitId.new(), 6, WRITER, "", (self.b,))
        store.apply_commit(second, [self.revision(second, self.other, b"")])

    def revision(
        self, record: CommitRecord, item: ItemId, data: bytes, **changes: object
    ) -> Revision:
        chunk = record.chunks[0]
        previous = self.store.latest([item]).get(item)
        inserted = previous.insert_time if previous else record.time
        revision = Revision(
            item, TABLE, chunk, data, inserted, record.time, False, WRITER, record.id
        )
        return dataclasses.replace(revision, **changes)  # type: ignore[arg-type]

    def batch(self, **changes: object) -> tuple[CommitRecord, list[Revision]]:
        """A valid batch at time 9 updating `old` and inserting a new item in `a`."""
        record = CommitRecord(CommitId.new(), 9, WRITER, "m", (self.a,))
        data = Counter(value=2).SerializeToString()
        update = self.revision(record, self.old, data)
        insert = self.revision(record, ItemId.new(), data)
        return record, [dataclasses.replace(update, **changes), insert]  # type: ignore[arg-type]


@pytest.fixture
def world(tmp_path: Path) -> Iterator[World]:
    store = SqliteStore(tmp_path / "s.sqlite", create=True)
    yield World(store)
    store.close()


class TestCheckBatch:
    def test_a_real_batch_passes_and_applies(self, world: World) -> None:
        record, revisions = world.batch()
        check_batch(world.store, world.a, record, revisions, WRITER)
        world.store.apply_commit(record, revisions)
        check_batch(world.store, world.a, record, revisions, WRITER)  # the same commit again

    def test_an_empty_batch_only_locks_a_chunk_the_commit_does_not_list(self, world: World) -> None:
        record, _ = world.batch()
        check_batch(world.store, world.b, record, [], WRITER)  # a serializable read lock
        with pytest.raises(UsageError, match=r"lists chunk .* but its batch writes nothing"):
            check_batch(world.store, world.a, record, [], WRITER)
        _, revisions = world.batch()
        with pytest.raises(UsageError, match="does not list chunk"):
            check_batch(world.store, world.b, record, revisions, WRITER)

    def test_an_unknown_chunk(self, world: World) -> None:
        record, revisions = world.batch()
        with pytest.raises(ChunkNotFound):
            check_batch(world.store, ChunkId.new(), record, revisions, WRITER)

    @pytest.mark.parametrize(
        ("changes", "text"),
        [
            ({"table": "other"}, "is not filed under chunk"),
            ({"commit_id": CommitId.new()}, "is not filed under chunk"),
            ({"author": PeerId.new()}, "is not filed under chunk"),
            ({"update_time": 10}, "is stamped 10, its commit 9"),
            ({"insert_time": 7}, "changes the item's insert time"),
            ({"data": b"\xff\xff\xff"}, "does not parse"),
            ({"removed": True}, "removes the item but carries a payload"),
        ],
    )
    def test_a_revision_that_does_not_fit(
        self, world: World, changes: dict[str, object], text: str
    ) -> None:
        record, revisions = world.batch(**changes)
        with pytest.raises(UsageError, match=text):
            check_batch(world.store, world.a, record, revisions, WRITER)

    def test_another_writer_than_the_author(self, world: World) -> None:
        record, revisions = world.batch()
        with pytest.raises(UsageError, match="sent by"):
            check_batch(world.store, world.a, record, revisions, PeerId.new())

    def test_an_item_of_another_chunk(self, world: World) -> None:
        record, revisions = world.batch()
        stolen = world.revision(record, world.other, b"")
        with pytest.raises(UsageError, match=f"belongs to chunk {world.b.short}"):
            check_batch(world.store, world.a, record, [*revisions, stolen], WRITER)

    def test_a_time_not_after_the_items_newest_revision(self, world: World) -> None:
        record, revisions = world.batch()
        early = dataclasses.replace(record, time=5)
        stale = [dataclasses.replace(r, update_time=5) for r in revisions]
        with pytest.raises(UsageError, match="not after its newest revision"):
            check_batch(world.store, world.a, early, stale, WRITER)

    def test_a_new_item_with_an_old_insert_time(self, world: World) -> None:
        record, (_, insert) = world.batch()
        with pytest.raises(UsageError, match="is new here"):
            check_batch(
                world.store, world.a, record, [dataclasses.replace(insert, insert_time=1)], WRITER
            )

    def test_one_item_twice(self, world: World) -> None:
        record, (update, _) = world.batch()
        with pytest.raises(UsageError, match="appears twice"):
            check_batch(world.store, world.a, record, [update, update], WRITER)

    def test_a_payload_over_the_limit(self, world: World, monkeypatch: pytest.MonkeyPatch) -> None:
        monkeypatch.setattr(limits, "MAX_PAYLOAD_BYTES", 1)
        record, revisions = world.batch()
        with pytest.raises(LimitExceeded, match="MAX_PAYLOAD_BYTES"):
            check_batch(world.store, world.a, record, revisions, WRITER)
