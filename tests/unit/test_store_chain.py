"""Verifiable history in the store (issue 18 §3): every applied commit extends the
chains of the chunks it wrote, a replica taken in gets the chain of its history, an
older store gets its chains once, and a store rolled back behind its high-water
mark says so."""

from __future__ import annotations

import shutil
import sqlite3
from collections.abc import Iterator
from pathlib import Path

import pytest

from mapapi.core import chain
from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId
from mapapi.store import MemoryStore, SqliteStore
from mapapi.store.base import Divergence, ReplicaStore
from mapapi.store.mark import Mark, decode, encode, read
from mapapi.swarm.chain_check import check_chain

AUTHOR = PeerId.new()
A, B = sorted([ChunkId.new(), ChunkId.new()])


@pytest.fixture(params=["memory", "sqlite"])
def store(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[ReplicaStore]:
    made: ReplicaStore = (
        MemoryStore()
        if request.param == "memory"
        else SqliteStore(tmp_path / "s.sqlite", create=True)
    )
    for chunk in (A, B):
        if "t" not in made.tables():
            made.add_table("t", "google.protobuf.Struct")
        made.add_chunk(chunk, "t")
    yield made
    made.close()


def commit(time: int, *chunks: ChunkId, data: bytes = b"x") -> tuple[CommitRecord, list[Revision]]:
    """A commit at `time` inserting one item into each of `chunks`."""
    record = CommitRecord(CommitId.new(), time, AUTHOR, f"c{time}", tuple(sorted(chunks)))
    revisions = [
        Revision(ItemId.new(), "t", c, data, time, time, False, AUTHOR, record.id) for c in chunks
    ]
    return record, revisions


def history_chain(store: ReplicaStore, chunk: ChunkId) -> list[tuple[CommitId, bytes]]:
    """The chain `chunk`'s stored history gives (`chain.rebuild`)."""
    records = {c.id: c for c in store.chunk_commits(chunk)}
    return chain.rebuild(chunk, records, store.chunk_revisions(chunk))


class TestEveryCommitIsLinked:
    def test_each_chunk_a_commit_wrote_gets_its_link(self, store: ReplicaStore) -> None:
        for time, chunks in ((1, (A,)), (2, (A, B)), (3, (B,))):
            store.apply_commit(*commit(time, *chunks))
        assert store.chain_length(A) == 2
        assert store.chain_length(B) == 2
        for chunk in (A, B):
            assert store.chain_links(chunk) == history_chain(store, chunk)
            assert check_chain(store, chunk) == []

    def test_a_commit_reaching_a_holder_one_chunk_at_a_time_links_each_once(
        self, store: ReplicaStore
    ) -> None:
        record, revisions = commit(1, A, B)
        for chunk in (A, B, A):  # one batch per chunk, and one of them again
            store.apply_commit(record, [r for r in revisions if r.chunk_id == chunk])
        assert [store.chain_length(A), store.chain_length(B)] == [1, 1]
        assert store.chain_head(A) == chain.link(chain.GENESIS, A, record, revisions)

    def test_a_link_given_again_for_the_head_commit_is_not_added(self, store: ReplicaStore) -> None:
        """The log's apply path links through `apply_commit` too: a link it then adds
        for the same commit is the one already there."""
        record, revisions = commit(1, A)
        store.apply_commit(record, revisions)
        store.chain_link(A, record.id, b"\x01" * 32)
        assert store.chain_links(A) == history_chain(store, A)


def test_a_replica_taken_in_gets_the_chain_of_its_history(store: ReplicaStore) -> None:
    sender = MemoryStore()
    sender.add_table("t", "google.protobuf.Struct")
    sender.add_chunk(A, "t")
    for time in (1, 2, 3):
        sender.apply_commit(*commit(time, A))
    store.apply_commit(*commit(1, A, data=b"mine alone"))  # replaced by what arrives
    store.diverged(Divergence(A, AUTHOR, 1, "differs", 0.0))
    store.install_chunk(
        A, "t", "google.protobuf.Struct", sender.chunk_revisions(A), sender.chunk_commits(A), []
    )
    assert store.chain_links(A) == sender.chain_links(A)
    assert store.divergences() == []  # a fresh replica is compared afresh


def test_divergences_are_kept_until_the_chains_agree_past_them(store: ReplicaStore) -> None:
    other = PeerId.new()
    store.diverged(Divergence(A, other, 3, "commit 3 differs", 0.0))
    (found,) = store.divergences()
    assert (found.chunk, found.peer, found.position) == (A, other, 3)
    assert found.noticed > 0
    store.agreed(A, other, 2)
    assert store.divergences() != []
    store.agreed(A, other, 3)
    assert store.divergences() == []


def test_the_chain_is_the_replicas_and_outlives_its_raft_group(store: ReplicaStore) -> None:
    store.raft_save(A, hard=(1, 0, 0))
    store.apply_commit(*commit(1, A))
    store.raft_drop(A)
    assert store.chain_length(A) == 1
    store.diverged(Divergence(A, AUTHOR, 1, "differs", 0.0))
    store.drop_chunk(A)  # the replica goes, and what other holders' chains showed of it
    assert store.divergences() == []


# -- SQLite only: an older store, the high-water mark -------------------------------------
def sqlite_store(path: Path) -> SqliteStore:
    made = SqliteStore(path, create=True)
    made.add_table("t", "google.protobuf.Struct")
    made.add_chunk(A, "t")
    return made


def test_an_older_store_gets_its_chains_once_when_opened(tmp_path: Path) -> None:
    path = tmp_path / "old.sqlite"
    made = sqlite_store(path)
    for time in (1, 2, 3):
        made.apply_commit(*commit(time, A))
    links = made.chain_links(A)
    made.close()
    con = sqlite3.connect(path)  # as a store written before commits were linked and counted
    con.execute("DELETE FROM raft_chain")
    con.execute("DELETE FROM meta WHERE key IN ('chains', 'applied')")
    con.commit()
    con.close()
    again = SqliteStore(path)
    assert again.chain_links(A) == links
    assert again.get_meta("applied") == "3"
    again.close()


def test_a_torn_mark_is_no_mark() -> None:
    whole = encode(Mark(12, 40, "ab" * 16))
    assert decode(whole) == Mark(12, 40, "ab" * 16)
    assert decode(whole.replace(b"applied=12", b"applied=13")) is None  # half written
    assert decode(b"") is None


def test_the_mark_follows_every_commit(tmp_path: Path) -> None:
    made = sqlite_store(tmp_path / "s.sqlite")
    record = None
    for time in (1, 2):
        record, revisions = commit(time, A)
        made.apply_commit(record, revisions)
    mark = read(tmp_path / "s.mark")
    assert mark is not None
    assert record is not None
    assert (mark.applied, mark.time, mark.commit) == (2, 2, record.id)
    assert made.rollbacks() == []
    made.close()


def copy_files(src: Path, dst: Path) -> None:
    """Copy a store's database files (the -wal and -shm too), as a backup would."""
    dst.mkdir()
    for f in src.parent.glob(src.name + "*"):
        shutil.copy2(f, dst / f.name)


def test_a_store_put_back_behind_its_mark_says_how_many_commits_it_lost(tmp_path: Path) -> None:
    path = tmp_path / "s.sqlite"
    made = sqlite_store(path)
    for time in range(1, 4):
        made.apply_commit(*commit(time, A))
    copy_files(path, tmp_path / "copy")  # mid-way, while the commits sit in the -wal
    for time in range(4, 9):
        made.apply_commit(*commit(time, A))
    made.close()
    for f in (tmp_path / "copy").iterdir():
        shutil.copy2(f, tmp_path / f.name)  # the older files put back; the mark stays
    for f in tmp_path.glob("s.sqlite-*"):
        if not (tmp_path / "copy" / f.name).exists():
            f.unlink()
    back = SqliteStore(path)
    (found,) = back.rollbacks()
    assert (found.recorded, found.stored, found.missing, found.noticed) == (8, 3, 5, 0.0)
    back.apply_commit(*commit(9, A))  # the first write records it before the mark moves on
    (kept,) = back.rollbacks()
    assert (kept.missing, kept.noticed > 0) == (5, True)
    back.accept_rollback()
    assert back.rollbacks() == []
    back.close()
    reopened = SqliteStore(path)
    assert reopened.rollbacks() == []
    reopened.close()
