"""The SQLite store's label index (mapapi.store.labels, sqlite_labels, sqlite_labelled):
reads of one label at any time, and summaries that equal a count from scratch
after every commit, replayed commit, installed replica and dropped replica,
whichever store wrote them."""

from __future__ import annotations

import random
from collections.abc import Iterator
from pathlib import Path

import pytest

from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId
from mapapi.store import SqliteStore
from mapapi.store.labels import Labels, LabelSummary, RowLabel, summarise
from mapapi.store.sqlite_labelled import LabelledSqliteStore
from mapapi.store.sqlite_labels import FLAG
from tests.unit.query_plans import plans_of

AUTHOR = PeerId.new()
TOY = "toy.Row"


def _toy(data: bytes) -> RowLabel | None:
    """b"A:3:1,2,0": label A, weight 3, at the point (1, 2, 0); b"A:1:" has no place."""
    label, weight, where = data.decode().split(":")
    if not label:
        return None
    if not where:
        return RowLabel(label, int(weight))
    x, y, z = (float(v) for v in where.split(","))
    return RowLabel(label, int(weight), (x, y, z, x, y, z))


LABELS = Labels({TOY: _toy})


class Toy:
    """Commits of toy rows to a store with tables t (labelled) and u (not)."""

    def __init__(
        self, store: SqliteStore, *, tables: bool = True, chunks: list[ChunkId] | None = None
    ) -> None:
        self.store = store
        self.time = store.clock()
        self.chunks = chunks or [ChunkId.new(), ChunkId.new()]
        self.plain = ChunkId.new()
        if tables:
            store.add_table("t", TOY)
            store.add_table("u", "toy.Other")
            for chunk in self.chunks:
                store.add_chunk(chunk, "t")
            store.add_chunk(self.plain, "u")

    def commit(
        self, *writes: tuple[ItemId, ChunkId, bytes | None]
    ) -> tuple[CommitRecord, list[Revision]]:
        """One commit; a write with data None removes the item."""
        self.time += 1
        record = CommitRecord(
            CommitId.new(), self.time, AUTHOR, "", tuple(sorted({c for _, c, _ in writes}))
        )
        revisions = []
        for item, chunk, data in writes:
            history = self.store.history(item)
            inserted = history[0].insert_time if history else self.time
            table = "u" if chunk == self.plain else "t"
            revisions.append(
                Revision(
                    item,
                    table,
                    chunk,
                    data or b"",
                    inserted,
                    self.time,
                    data is None,
                    AUTHOR,
                    record.id,
                )
            )
        self.store.apply_commit(record, revisions)
        return record, revisions


def _oracle(store: SqliteStore) -> list[LabelSummary]:
    """The summaries counted from scratch from the store's rows now."""
    return summarise(store.scan(store.clock()), LABELS, store.tables())


def _ids(revisions: list[Revision]) -> list[ItemId]:
    return [r.item_id for r in revisions]


@pytest.fixture
def store(tmp_path: Path) -> Iterator[LabelledSqliteStore]:
    made = LabelledSqliteStore(tmp_path / "s.sqlite", LABELS, create=True)
    yield made
    made.close()


def test_a_label_reads_its_rows_at_any_time(store: LabelledSqliteStore) -> None:
    toy = Toy(store)
    c = toy.chunks[0]
    a1, a2, b1 = ItemId.new(), ItemId.new(), ItemId.new()
    toy.commit((a1, c, b"A:1:0,0,0"), (a2, c, b"A:1:1,0,0"), (b1, c, b"B:1:5,5,0"))  # time 1
    toy.commit((a2, c, b"B:1:1,0,0"))  # 2: a2 moves to B
    toy.commit((a1, c, None))  # 3: a1 is removed

    def read(label: str, time: int) -> list[ItemId]:
        return _ids(store.scan_labelled(time, label, table="t"))

    assert read("A", 1) == sorted([a1, a2])
    assert (read("A", 2), read("A", 3)) == ([a1], [])
    assert (read("B", 1), read("B", 2)) == ([b1], sorted([a2, b1]))
    assert read("A", 0) == []
    assert store.scan_labelled(3, "B", table="u") == []
    assert store.scan_labelled(3, "B", chunk=toy.chunks[1]) == []
    assert [r.data for r in store.scan_labelled(3, "B") if r.item_id == a2] == [b"B:1:1,0,0"]


def test_summaries_equal_a_count_from_scratch_after_every_commit(
    store: LabelledSqliteStore,
) -> None:
    toy = Toy(store)
    rng = random.Random(14)
    live: dict[ItemId, ChunkId] = {}
    for _ in range(60):
        writes: list[tuple[ItemId, ChunkId, bytes | None]] = []
        for _ in range(rng.randint(1, 6)):
            label = rng.choice("ABC")
            data = f"{label}:{rng.randint(1, 9)}:{rng.uniform(-9, 9)},{rng.uniform(-9, 9)},0"
            kind = rng.random()
            chosen = {w[0] for w in writes}
            present = [i for i in live if i not in chosen]
            if present and kind < 0.3:
                item = rng.choice(present)
                writes.append((item, live.pop(item), None))
            elif present and kind < 0.6:
                item = rng.choice(present)
                writes.append((item, live[item], data.encode()))
            else:
                item, chunk = ItemId.new(), rng.choice(toy.chunks)
                live[item] = chunk
                writes.append((item, chunk, data.encode()))
        record, revisions = toy.commit(*writes)
        assert store.label_summaries() == _oracle(store)
        store.apply_commit(record, revisions)  # a commit reaching this holder twice
        assert store.label_summaries() == _oracle(store)
    assert {s.label for s in store.label_summaries()} <= {"A", "B", "C"}
    assert store.label_summaries(["A"]) == [s for s in _oracle(store) if s.label == "A"]


def test_a_commit_applied_one_chunk_at_a_time_counts_once(store: LabelledSqliteStore) -> None:
    toy = Toy(store)
    one, two = toy.chunks
    record = CommitRecord(CommitId.new(), 1, AUTHOR, "", (one, two))
    revisions = [
        Revision(ItemId.new(), "t", chunk, b"A:2:0,0,0", 1, 1, False, AUTHOR, record.id)
        for chunk in (one, two, two)
    ]
    store.apply_commit(record, revisions[:1])
    store.apply_commit(record, revisions)  # the second chunk's batch repeats nothing of the first

    assert [(s.chunk, s.items, s.weight) for s in store.label_summaries()] == sorted(
        [(one, 1, 2), (two, 2, 4)], key=lambda s: s[0]
    )
    assert store.label_summaries() == _oracle(store)


def test_an_installed_replica_replaces_what_the_index_had_and_a_dropped_one_goes(
    store: LabelledSqliteStore, tmp_path: Path
) -> None:
    toy = Toy(store)
    c = toy.chunks[0]
    stale = ItemId.new()
    toy.commit((stale, c, b"A:1:0,0,0"))
    source = LabelledSqliteStore(tmp_path / "holder.sqlite", LABELS, create=True)
    try:
        other = Toy(source, chunks=[c])  # the holder's replica of the same chunk
        kept, moved = ItemId.new(), ItemId.new()
        other.commit((kept, c, b"A:4:1,1,1"), (moved, c, b"A:1:2,2,2"))
        other.commit((moved, c, b"B:1:3,3,3"))
        revisions, commits = source.chunk_revisions(c), source.chunk_commits(c)
        store.install_chunk(c, "t", TOY, revisions, commits, [AUTHOR])
    finally:
        source.close()

    assert [(s.label, s.items, s.weight, s.box) for s in store.label_summaries()] == [
        ("A", 1, 4, (1.0, 1.0, 1.0, 1.0, 1.0, 1.0)),
        ("B", 1, 1, (3.0, 3.0, 3.0, 3.0, 3.0, 3.0)),
    ]
    assert store.label_summaries() == _oracle(store)
    assert _ids(store.scan_labelled(store.clock(), "A")) == [kept]
    assert _ids(store.scan_labelled(1, "A")) == sorted([kept, moved])  # the replica's history

    store.drop_chunk(c)
    assert store.label_summaries() == []
    assert store.scan_labelled(store.clock(), "A") == []
    count = store._con().execute("SELECT COUNT(*) FROM labelled").fetchone()[0]
    assert count == 0


def test_what_a_store_without_labels_writes_is_labelled_on_next_use(
    store: LabelledSqliteStore,
) -> None:
    toy = Toy(store)
    c = toy.chunks[0]
    first = ItemId.new()
    toy.commit((first, c, b"A:1:0,0,0"))
    plain = SqliteStore(store.path)  # another process, built without the labels
    try:
        behind = Toy(plain, tables=False)
        later = ItemId.new()
        behind.commit((later, c, b"A:1:9,9,9"))
    finally:
        plain.close()
    toy.time = store.clock()
    toy.commit((ItemId.new(), c, b"A:1:1,1,1"))  # the labelled store sees the index is behind

    (summary,) = store.label_summaries()
    assert (summary.items, summary.box) == (3, (0.0, 0.0, 0.0, 9.0, 9.0, 9.0))
    assert later in _ids(store.scan_labelled(store.clock(), "A"))
    assert store.label_summaries() == _oracle(store)

    plain = SqliteStore(store.path)
    try:
        plain.drop_chunk(c)
    finally:
        plain.close()
    assert store.label_summaries() == []


def test_an_index_of_other_labels_or_other_tables_is_made_anew(tmp_path: Path) -> None:
    path = tmp_path / "s.sqlite"
    store = LabelledSqliteStore(path, LABELS, create=True)
    toy = Toy(store)
    item = ItemId.new()
    toy.commit((item, toy.chunks[0], b"A:1:0,0,0"))
    store._con().execute("DROP TABLE label_sets")
    store._con().execute("CREATE TABLE label_sets (id INTEGER PRIMARY KEY, label TEXT)")
    store.close()

    again = LabelledSqliteStore(path, LABELS)
    try:
        assert _ids(again.scan_labelled(again.clock(), "A")) == [item]
        assert again.label_summaries() == _oracle(again)
    finally:
        again.close()
    relabelled = Labels({TOY: lambda data: RowLabel("all")}, version="2")
    other = LabelledSqliteStore(path, relabelled)
    try:
        assert [s.label for s in other.label_summaries()] == ["all"]
        flag = other._con().execute("SELECT value FROM meta WHERE key = ?", (FLAG,)).fetchone()
        assert flag[0] == relabelled.signature
    finally:
        other.close()


def test_a_read_of_one_label_seeks_its_rows_through_the_indexes(
    store: LabelledSqliteStore,
) -> None:
    toy = Toy(store)
    toy.commit(*((ItemId.new(), c, b"A:1:0,0,0") for c in toy.chunks))

    (plan,) = plans_of(store, lambda: store.scan_labelled(store.clock(), "A", table="t"))

    assert any(s.startswith("SEARCH l USING PRIMARY KEY (label_set=?)") for s in plan), plan
    assert any(
        s.startswith("SEARCH r USING PRIMARY KEY (item_id=? AND update_time=?)") for s in plan
    ), plan
    assert not any(s.startswith("SCAN") for s in plan), plan


def test_a_scan_of_one_chunk_reads_that_chunk_through_its_index(
    store: LabelledSqliteStore,
) -> None:
    toy = Toy(store)
    toy.commit(*((ItemId.new(), c, b"A:1:0,0,0") for c in toy.chunks))

    (plan,) = plans_of(store, lambda: store.scan(store.clock(), table="t", chunk=toy.chunks[0]))

    # the chunk's rows alone, not every chunk of the table (`ls TABLE --chunk`)
    assert "SEARCH r USING INDEX revisions_chunk_time (chunk_no=?)" in plan, plan
    assert not any(step.startswith("SCAN r") for step in plan), plan
