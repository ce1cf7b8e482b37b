"""The Raft state of a chunk's group in the store (DESIGN §13): persisted per the Ready
order contract, reloaded after a restart, and applied together with its effect."""

from __future__ import annotations

import sqlite3
from collections.abc import Iterator
from pathlib import Path

import pytest

from mapapi.core.history import CommitRecord
from mapapi.core.ids import ChunkId, CommitId, PeerId
from mapapi.store.base import LogRow, Store
from mapapi.store.memory import MemoryStore
from mapapi.store.sqlite import SqliteStore

CHUNK = ChunkId("0123456789abcdef0123456789abcdef")


def rows(*terms: int, start: int = 1) -> list[LogRow]:
    """Entries at consecutive indices from `start`, with these terms."""
    return [LogRow(start + i, term, 1, f"e{start + i}".encode()) for i, term in enumerate(terms)]


@pytest.fixture(params=["memory", "sqlite"])
def store(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[Store]:
    made: Store = (
        MemoryStore()
        if request.param == "memory"
        else SqliteStore(tmp_path / "s.sqlite", create=True)
    )
    yield made
    made.close()


class TestPersist:
    def test_nothing_persisted_is_none(self, store: Store) -> None:
        assert store.raft_load(CHUNK) is None

    def test_entries_and_hard_state_come_back(self, store: Store) -> None:
        store.raft_save(CHUNK, hard=(2, 7, 1), entries=rows(1, 2))
        kept = store.raft_load(CHUNK)
        assert kept is not None
        assert (kept.term, kept.vote, kept.commit, kept.applied) == (2, 7, 1, 0)
        assert list(kept.entries) == rows(1, 2)

    def test_entries_replace_the_log_from_their_first_index(self, store: Store) -> None:
        store.raft_save(CHUNK, entries=rows(1, 1, 1, 1))
        store.raft_save(CHUNK, entries=rows(3, start=3))  # a new leader overwrote 3 and 4
        kept = store.raft_load(CHUNK)
        assert kept is not None
        assert [(e.index, e.term) for e in kept.entries] == [(1, 1), (2, 1), (3, 3)]

    def test_a_snapshot_replaces_the_whole_log(self, store: Store) -> None:
        store.raft_save(CHUNK, entries=rows(1, 1, 2, 2, 2))  # 4 and 5: a branch that lost
        store.raft_save(CHUNK, snapshot=(3, 2, b"1,2;", b"state"), entries=rows(3, start=4))
        kept = store.raft_load(CHUNK)
        assert kept is not None
        assert (kept.snap_index, kept.snap_term, kept.snap_config, kept.snap_data) == (
            3,
            2,
            b"1,2;",
            b"state",
        )
        assert [(e.index, e.term) for e in kept.entries] == [(4, 3)]
        assert kept.commit == 3  # a snapshot holds committed state only

    def test_drop_forgets_the_group(self, store: Store) -> None:
        store.raft_save(CHUNK, hard=(1, 0, 0), entries=rows(1))
        store.raft_drop(CHUNK)
        assert store.raft_load(CHUNK) is None


class TestApplied:
    def test_the_applied_index_only_moves_forward(self, store: Store) -> None:
        store.raft_save(CHUNK, entries=rows(1, 1, 1))
        store.raft_applied(CHUNK, 2)
        with pytest.raises(ValueError, match="behind"):
            store.raft_applied(CHUNK, 1)  # applying entry 2 again would apply it twice
        kept = store.raft_load(CHUNK)
        assert kept is not None
        assert kept.applied == 2

    def test_no_group_no_applied_index(self, store: Store) -> None:
        with pytest.raises(ValueError, match="no Raft state"):
            store.raft_applied(CHUNK, 1)


class TestSqlite:
    def test_an_entry_and_its_effect_land_together_or_not_at_all(self, tmp_path: Path) -> None:
        store = SqliteStore(tmp_path / "s.sqlite", create=True)
        store.add_table("t", "google.protobuf.Struct")
        store.add_chunk(CHUNK, "t")
        store.raft_save(CHUNK, entries=rows(1))
        record = CommitRecord(CommitId.new(), 5, PeerId.new(), "m", (CHUNK,))

        def interrupted() -> None:
            with store.exclusive():
                store.apply_commit(record, [])
                store.raft_applied(CHUNK, 1)
                raise RuntimeError("crash between the effect and the next statement")

        with pytest.raises(RuntimeError):
            interrupted()
        kept = store.raft_load(CHUNK)
        assert kept is not None
        assert (kept.applied, store.commit_record(record.id)) == (0, None)
        with store.exclusive():
            store.apply_commit(record, [])
            store.raft_applied(CHUNK, 1)
        kept = store.raft_load(CHUNK)
        assert kept is not None
        assert (kept.applied, store.commit_record(record.id)) == (1, record)
        store.close()

    def test_state_survives_reopening(self, tmp_path: Path) -> None:
        path = tmp_path / "s.sqlite"
        first = SqliteStore(path, create=True)
        first.raft_save(CHUNK, hard=(4, 2, 3), entries=rows(1, 4, 4))
        first.close()
        again = SqliteStore(path)
        kept = again.raft_load(CHUNK)
        again.close()
        assert kept is not None
        assert (kept.term, kept.vote, kept.commit, len(kept.entries)) == (4, 2, 3, 3)

    def test_a_store_from_before_raft_gains_its_tables(self, tmp_path: Path) -> None:
        path = tmp_path / "s.sqlite"
        SqliteStore(path, create=True).close()
        con = sqlite3.connect(path)
        con.execute("DROP TABLE raft_log")
        con.execute("DROP TABLE raft_state")
        con.commit()
        con.close()
        store = SqliteStore(path)
        store.raft_save(CHUNK, entries=rows(1))
        kept = store.raft_load(CHUNK)
        store.close()
        assert kept is not None
        assert len(kept.entries) == 1
