"""The `Store` protocol, on both implementations (mapapi.store)."""

import sqlite3
from collections.abc import Iterator
from pathlib import Path

import pytest

from mapapi import ChunkNotFound, CorruptRepoError, UsageError
from mapapi.core.codec import revision_from_pb
from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId
from mapapi.store import ChunkInfo, MemoryStore, SqliteStore, Store

AUTHOR = PeerId.new()


def ident(kind: type, prefix: str, n: int = 0) -> ItemId:
    return kind(prefix + f"{n:x}".rjust(32 - len(prefix), "0"))


@pytest.fixture(params=["memory", "sqlite"])
def store(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[Store]:
    made: Store = (
        MemoryStore()
        if request.param == "memory"
        else SqliteStore(tmp_path / "s.sqlite", create=True)
    )
    yield made
    made.close()


class Writer:
    """Builds commits of revisions against a store with tables t and u."""

    def __init__(self, store: Store) -> None:
        self.store = store
        store.add_table("t", "google.protobuf.Struct")
        store.add_table("u", "mapapi.v1.Counter")
        self.c1, self.c2, self.cu = ChunkId.new(), ChunkId.new(), ChunkId.new()
        store.add_chunk(self.c1, "t")
        store.add_chunk(self.c2, "t")
        store.add_chunk(self.cu, "u")

    def commit(
        self, time: int, *writes: tuple[ItemId, ChunkId, bytes | None], message: str = ""
    ) -> CommitRecord:
        """Apply one commit at `time`; a write with data None is a removal."""
        record = CommitRecord(
            CommitId.new(), time, AUTHOR, message, tuple(sorted({c for _, c, _ in writes}))
        )
        self.store.apply_commit(record, self.revisions(record, writes))
        return record

    def revisions(
        self, record: CommitRecord, writes: tuple[tuple[ItemId, ChunkId, bytes | None], ...]
    ) -> list[Revision]:
        out = []
        for item, chunk, data in writes:
            history = self.store.history(item)
            inserted = history[0].insert_time if history else record.time
            table = "u" if chunk == self.cu else "t"
            out.append(
                Revision(
                    item,
                    table,
                    chunk,
                    data or b"",
                    inserted,
                    record.time,
                    data is None,
                    AUTHOR,
                    record.id,
                )
            )
        return out


@pytest.fixture
def writer(store: Store) -> Writer:
    return Writer(store)


class TestEmptyStore:
    def test_is_empty(self, store: Store) -> None:
        assert store.clock() == 0
        assert store.tables() == {}
        assert store.chunks() == []
        assert store.commits() == []
        assert store.views() == {}
        assert store.read(ItemId.new(), 10) is None
        assert store.history(ItemId.new()) == []
        assert store.scan(10) == []
        assert store.latest([ItemId.new()]) == {}
        assert store.changed_since(0) == []


class TestTablesAndChunks:
    def test_tables_by_name(self, store: Store) -> None:
        store.add_table("b", "mapapi.v1.Counter")
        store.add_table("a", "google.protobuf.Struct")
        assert store.tables() == {"a": "google.protobuf.Struct", "b": "mapapi.v1.Counter"}

    def test_table_names_are_unique(self, store: Store) -> None:
        store.add_table("a", "google.protobuf.Struct")
        with pytest.raises(UsageError, match="already exists"):
            store.add_table("a", "mapapi.v1.Counter")
        assert store.tables() == {"a": "google.protobuf.Struct"}

    def test_chunk_of_an_unknown_table_is_refused(self, store: Store) -> None:
        with pytest.raises(UsageError, match="no table 'nope'"):
            store.add_chunk(ChunkId.new(), "nope")
        assert store.chunks() == []

    def test_chunk_table(self, writer: Writer) -> None:
        assert writer.store.chunk_table(writer.c1) == "t"
        assert writer.store.chunk_table(writer.cu) == "u"
        with pytest.raises(ChunkNotFound):
            writer.store.chunk_table(ChunkId.new())

    def test_a_chunk_has_its_own_replication_factor_or_its_tables(self, store: Store) -> None:
        assert isinstance(store, MemoryStore | SqliteStore)  # both are ReplicaStores
        store.add_table("wide", "google.protobuf.Struct", replication=5)
        store.add_table("plain", "google.protobuf.Struct")
        inherits, own, default = ChunkId.new(), ChunkId.new(), ChunkId.new()
        store.add_chunk(inherits, "wide")
        store.add_chunk(own, "wide", replication=1)
        store.add_chunk(default, "plain")
        store.add_chunk(own, "wide", replication=3)  # known already: keeps its own

        assert [store.replication(c) for c in (inherits, own, default)] == [5, 1, 0]
        store.set_replication(default, 7)  # as a holder's state says
        assert store.replication(default) == 7
        with pytest.raises(ChunkNotFound):
            store.replication(ChunkId.new())

    def test_adding_a_chunk_twice_is_harmless(self, writer: Writer) -> None:
        writer.store.add_chunk(writer.c1, "t")
        assert len(writer.store.chunks("t")) == 2

    def test_chunks_count_live_items_and_their_bytes_now(self, writer: Writer) -> None:
        a, b, c, d = (ItemId.new() for _ in range(4))
        writer.commit(1, (a, writer.c1, b"a"), (b, writer.c1, b"b"), (c, writer.c2, b"c"))
        writer.commit(2, (b, writer.c1, None), (a, writer.c1, b"a22"), (d, writer.cu, b"dd"))
        counts = {info.id: info for info in writer.store.chunks()}
        assert counts == {
            writer.c1: ChunkInfo(writer.c1, "t", 1, 3),  # a's newest revision only
            writer.c2: ChunkInfo(writer.c2, "t", 1, 1),
            writer.cu: ChunkInfo(writer.cu, "u", 1, 2),
        }
        assert writer.store.chunks(only=writer.c2) == [ChunkInfo(writer.c2, "t", 1, 1)]
        assert writer.store.chunks("u", only=writer.c2) == []
        assert writer.store.chunks(only=ChunkId.new()) == []

    def test_chunks_of_one_table_sorted_by_id(self, writer: Writer) -> None:
        listed = writer.store.chunks("t")
        assert [c.id for c in listed] == sorted([writer.c1, writer.c2])
        assert all(c.items == 0 for c in listed)
        assert writer.store.chunks("nope") == []


class TestReplicas:
    def test_a_dropped_chunk_installs_again_whole(self, store: Store, writer: Writer) -> None:
        assert isinstance(store, MemoryStore | SqliteStore)  # both are ReplicaStores
        item = ItemId.new()
        writer.commit(1, (item, writer.c1, b"x"))
        writer.commit(2, (item, writer.c1, b"y"), (ItemId.new(), writer.c2, b"z"))
        revisions = store.chunk_revisions(writer.c1)
        commits = store.chunk_commits(writer.c1)
        store.drop_chunk(writer.c1)
        assert store.history(item) == []

        store.install_chunk(writer.c1, "t", "google.protobuf.Struct", revisions, commits, [AUTHOR])

        assert store.chunk_revisions(writer.c1) == revisions
        assert [r.data for r in store.history(item)] == [b"x", b"y"]

    def test_a_chunks_history_as_wire_messages_is_its_typed_history(
        self, store: Store, writer: Writer
    ) -> None:
        assert isinstance(store, MemoryStore | SqliteStore)
        item = ItemId.new()
        writer.commit(1, (item, writer.c1, b"x"))
        writer.commit(2, (item, writer.c1, None), (ItemId.new(), writer.c1, b"z"))

        wire = store.chunk_revisions_pb(writer.c1)

        assert [revision_from_pb(m) for m in wire] == store.chunk_revisions(writer.c1)
        assert [m.removed for m in wire].count(True) == 1

    @pytest.mark.parametrize(
        "damage",
        [
            "UPDATE revisions SET item_id = x'abcd'",  # an item id is 16 bytes
            "UPDATE commits SET author = 'abc'",  # a row's author is its commit's
        ],
    )
    def test_a_damaged_id_in_a_chunks_history_is_named(self, tmp_path: Path, damage: str) -> None:
        store = SqliteStore(tmp_path / "s.sqlite", create=True)
        writer = Writer(store)
        item = ItemId.new()
        writer.commit(1, (item, writer.c1, b"x"))
        con = sqlite3.connect(tmp_path / "s.sqlite")
        con.execute(damage)
        con.commit()
        con.close()
        try:
            with pytest.raises(CorruptRepoError, match="revision"):
                store.chunk_revisions_pb(writer.c1)
        finally:
            store.close()


class TestRevisions:
    def test_read_at_time(self, writer: Writer) -> None:
        a = ItemId.new()
        writer.commit(1, (a, writer.c1, b"v1"))
        writer.commit(3, (a, writer.c1, b"v3"))
        writer.commit(5, (a, writer.c1, None))
        read = writer.store.read
        assert read(a, 0) is None
        assert [read(a, t).data for t in (1, 2, 3, 4)] == [b"v1", b"v1", b"v3", b"v3"]
        tombstone = read(a, 9)
        assert tombstone is not None
        assert tombstone.removed
        assert tombstone.data == b""
        assert tombstone.insert_time == 1

    def test_history_oldest_first(self, writer: Writer) -> None:
        a = ItemId.new()
        first = writer.commit(1, (a, writer.c1, b"v1"))
        second = writer.commit(4, (a, writer.c1, None))
        history = writer.store.history(a)
        assert [(r.update_time, r.removed, r.commit_id) for r in history] == [
            (1, False, first.id),
            (4, True, second.id),
        ]
        assert history[0] == Revision(a, "t", writer.c1, b"v1", 1, 1, False, AUTHOR, first.id)

    def test_scan_at_time_excludes_tombstones(self, writer: Writer) -> None:
        a, b, c, d = sorted(ItemId.new() for _ in range(4))
        writer.commit(1, (a, writer.c1, b"a"), (b, writer.c1, b"b"), (c, writer.c2, b"c"))
        writer.commit(2, (b, writer.c1, None), (d, writer.cu, b"d"))
        writer.commit(3, (a, writer.c1, b"a3"))

        def scan(time: int, **scope: object) -> list[tuple[ItemId, bytes]]:
            return [(r.item_id, r.data) for r in writer.store.scan(time, **scope)]  # type: ignore[arg-type]

        assert scan(0) == []
        assert scan(1) == [(a, b"a"), (b, b"b"), (c, b"c")]
        assert scan(2) == [(a, b"a"), (c, b"c"), (d, b"d")]
        assert scan(3, table="t") == [(a, b"a3"), (c, b"c")]
        assert scan(3, chunk=writer.c2) == [(c, b"c")]
        assert scan(1, table="t", chunk=writer.c1) == [(a, b"a"), (b, b"b")]
        assert scan(3, table="u", chunk=writer.c1) == []

    def test_latest_includes_tombstones_and_skips_unknown(self, writer: Writer) -> None:
        a, b = ItemId.new(), ItemId.new()
        writer.commit(1, (a, writer.c1, b"a"), (b, writer.c1, b"b"))
        writer.commit(2, (b, writer.c1, None))
        latest = writer.store.latest([a, b, ItemId.new()])
        assert set(latest) == {a, b}
        assert latest[a].data == b"a"
        assert latest[b].removed
        assert latest[b].update_time == 2

    def test_latest_of_many_items(self, writer: Writer) -> None:
        items = [ItemId.new() for _ in range(1200)]
        writer.commit(1, *((i, writer.c1, b"x") for i in items))
        assert set(writer.store.latest([*items, ItemId.new()])) == set(items)

    def test_changed_since(self, writer: Writer) -> None:
        a, b, c = ItemId.new(), ItemId.new(), ItemId.new()
        writer.commit(1, (a, writer.c1, b"a"))
        writer.commit(2, (b, writer.c2, b"b"), (c, writer.cu, b"c"))
        writer.commit(3, (a, writer.c1, None))

        def since(time: int, **scope: object) -> list[tuple[ItemId, int]]:
            found = writer.store.changed_since(time, **scope)  # type: ignore[arg-type]
            return [(r.item_id, r.update_time) for r in found]

        assert since(0, table="t") == [(a, 1), (b, 2), (a, 3)]
        assert since(1) == [*sorted([(b, 2), (c, 2)], key=lambda x: (x[1], x[0])), (a, 3)]
        assert since(1, chunk=writer.c1) == [(a, 3)]
        assert since(3) == []


class TestCommits:
    def test_apply_commit_advances_the_clock(self, writer: Writer) -> None:
        writer.commit(7, (ItemId.new(), writer.c1, b"x"))
        assert writer.store.clock() == 7
        writer.commit(4, (ItemId.new(), writer.c1, b"y"))  # a late, older commit
        assert writer.store.clock() == 7

    def test_apply_commit_is_idempotent(self, writer: Writer) -> None:
        a = ItemId.new()
        record = CommitRecord(CommitId.new(), 3, AUTHOR, "once", (writer.c1,))
        revisions = writer.revisions(record, ((a, writer.c1, b"x"),))
        writer.store.apply_commit(record, revisions)
        writer.store.apply_commit(record, revisions)
        assert writer.store.history(a) == revisions
        assert writer.store.commits() == [record]
        assert writer.store.clock() == 3

    def test_commit_inside_exclusive_section(self, writer: Writer) -> None:
        with writer.store.exclusive():
            record = writer.commit(2, (ItemId.new(), writer.c1, b"x"))
        assert writer.store.commit_record(record.id) == record

    def test_commits_newest_first(self, writer: Writer) -> None:
        records = [writer.commit(t, (ItemId.new(), writer.c1, b"x")) for t in (2, 5, 3)]
        newest = sorted(records, key=lambda r: r.time, reverse=True)
        assert writer.store.commits() == newest
        assert writer.store.commits(limit=2) == newest[:2]
        assert writer.store.commits(limit=0) == []

    def test_commit_record_and_revisions(self, writer: Writer) -> None:
        a, b = sorted([ItemId.new(), ItemId.new()])
        record = writer.commit(2, (a, writer.c1, b"a"), (b, writer.c2, None), message="hello")
        assert writer.store.commit_record(record.id) == record
        stored = writer.store.commit_record(record.id)
        assert stored is not None
        assert stored.message == "hello"
        assert stored.chunks == tuple(sorted([writer.c1, writer.c2]))
        written = sorted(writer.store.commit_revisions(record.id), key=lambda r: r.item_id)
        assert [(r.item_id, r.removed) for r in written] == [(a, False), (b, True)]
        assert writer.store.commit_record(CommitId.new()) is None
        assert writer.store.commit_revisions(CommitId.new()) == []


class TestResolvePrefix:
    def test_items(self, writer: Writer) -> None:
        ab1, ab2, cd = ident(ItemId, "ab", 1), ident(ItemId, "ab", 2), ident(ItemId, "cd")
        ab3 = ident(ItemId, "ab", 3)
        writer.commit(1, (ab1, writer.c1, b"x"), (ab2, writer.c1, b"x"), (cd, writer.c1, b"x"))
        writer.commit(2, (ab3, writer.c1, b"x"), (ab1, writer.c1, None))
        resolve = writer.store.resolve_prefix
        assert resolve("item", "cd") == [cd]
        assert resolve("item", str(ab2)) == [ab2]
        assert resolve("item", "ab") == [ab1, ab2]  # at most two: enough to see ambiguity
        assert resolve("item", "ef") == []

    def test_chunks_and_commits(self, store: Store) -> None:
        store.add_table("t", "google.protobuf.Struct")
        c1, c2 = ident(ChunkId, "c0ffee", 1), ident(ChunkId, "c0ffef", 2)
        store.add_chunk(c1, "t")
        store.add_chunk(c2, "t")
        record = CommitRecord(ident(CommitId, "beef"), 1, AUTHOR, "", (c1,))
        store.apply_commit(record, [])
        assert store.resolve_prefix("chunk", "c0ffee") == [c1]
        assert store.resolve_prefix("chunk", "c0ff") == [c1, c2]
        assert store.resolve_prefix("commit", "bee") == [record.id]
        assert store.resolve_prefix("commit", "c0ff") == []
        assert store.resolve_prefix("item", "c0ff") == []


class TestViews:
    def test_save_load_replace_delete(self, store: Store) -> None:
        assert store.load_view("main") is None
        store.save_view("main", b"one")
        store.save_view("other", b"\x00\xff")
        assert store.load_view("main") == b"one"
        store.save_view("main", b"two")
        assert store.views() == {"main": b"two", "other": b"\x00\xff"}
        store.delete_view("main")
        store.delete_view("never")
        assert store.load_view("main") is None
        assert store.views() == {"other": b"\x00\xff"}


class TestSqliteFile:
    def test_data_survives_reopening(self, tmp_path: Path) -> None:
        path = tmp_path / "s.sqlite"
        first = SqliteStore(path, create=True)
        writer = Writer(first)
        a = ItemId.new()
        record = writer.commit(3, (a, writer.c1, b"x"))
        first.save_view("main", b"v")
        first.close()
        again = SqliteStore(path)
        try:
            assert again.clock() == 3
            assert again.commits() == [record]
            assert [r.data for r in again.history(a)] == [b"x"]
            assert again.load_view("main") == b"v"
            assert len(again.chunks()) == 3
        finally:
            again.close()

    def test_create_on_an_existing_store_keeps_it(self, tmp_path: Path) -> None:
        path = tmp_path / "s.sqlite"
        first = SqliteStore(path, create=True)
        first.add_table("t", "google.protobuf.Struct")
        first.close()
        again = SqliteStore(path, create=True)
        try:
            assert again.tables() == {"t": "google.protobuf.Struct"}
        finally:
            again.close()

    def test_missing_file_is_corrupt(self, tmp_path: Path) -> None:
        with pytest.raises(CorruptRepoError, match="missing"):
            SqliteStore(tmp_path / "nope.sqlite")
        assert not (tmp_path / "nope.sqlite").exists()

    @pytest.mark.parametrize("create", [False, True])
    def test_garbage_file_is_corrupt(self, tmp_path: Path, create: bool) -> None:
        path = tmp_path / "s.sqlite"
        garbage = b"this is not a database at all\n" * 200
        path.write_bytes(garbage)
        with pytest.raises(CorruptRepoError, match="not a mapapi store"):
            SqliteStore(path, create=create)
        assert path.read_bytes() == garbage

    @pytest.mark.parametrize("create", [False, True])
    def test_foreign_sqlite_database_is_corrupt(self, tmp_path: Path, create: bool) -> None:
        path = tmp_path / "other.sqlite"
        con = sqlite3.connect(path)
        con.execute("CREATE TABLE songs (title TEXT)")
        con.commit()
        con.close()
        with pytest.raises(CorruptRepoError, match="not a mapapi store"):
            SqliteStore(path, create=create)
        con = sqlite3.connect(path)
        try:  # left as it was: no mapapi tables added to someone else's database
            names = [r[0] for r in con.execute("SELECT name FROM sqlite_master")]
            mode = con.execute("PRAGMA journal_mode").fetchone()[0]
        finally:
            con.close()
        assert names == ["songs"]
        assert mode == "delete"

    def test_foreign_database_with_a_meta_table_is_corrupt(self, tmp_path: Path) -> None:
        path = tmp_path / "other.sqlite"
        con = sqlite3.connect(path)
        con.execute("CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT NOT NULL)")
        con.execute("INSERT INTO meta VALUES ('format', 'something-else')")
        con.commit()
        con.close()
        with pytest.raises(CorruptRepoError, match="not a mapapi store"):
            SqliteStore(path)
