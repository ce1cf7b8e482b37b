"""Dropping old history (`mapctl gc`, issue 14 §4) in the SQLite store: every read
at or after the horizon reads what it read before, each item's newest revision
stays, the hash chains still check, and a replica taken from a compacted store
carries the chain its history can no longer rebuild."""

from __future__ import annotations

import tempfile
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mapapi import Peer, UsageError
from mapapi.core import codec
from mapapi.core.history import CommitRecord
from mapapi.core.ids import ChunkId, CommitId, ItemId
from mapapi.service.gc import GcOperations
from mapapi.store import MemoryStore, SqliteStore
from mapapi.store.base import ReplicaStore
from mapapi.swarm.chain_check import check_chain
from mapapi.swarm.chunk_state import StoreStates
from tests.unit.test_store import AUTHOR, Writer

ITEMS = [ItemId(f"{n:032x}") for n in range(1, 5)]

# a history: per commit, the items it writes (None: removes) and to which of two chunks
writes = st.lists(
    st.tuples(st.sampled_from(range(4)), st.booleans(), st.booleans()), min_size=1, max_size=4
)
histories = st.lists(writes, min_size=1, max_size=12)


def build(store: SqliteStore, history: list[list[tuple[int, bool, bool]]]) -> Writer:
    """Commit `history` at times 1, 2, ...; an item stays in the chunk it was first
    written to."""
    writer = Writer(store)
    home: dict[int, ChunkId] = {}
    for time, commit in enumerate(history, 1):
        chosen = {}
        for item, second, remove in commit:
            chunk = home.setdefault(item, writer.c2 if second else writer.c1)
            alive = store.read(ITEMS[item], time) is not None
            data = None if remove and alive else f"{item}@{time}".encode()
            chosen[item] = (ITEMS[item], chunk, data)
        writer.commit(time, *chosen.values())
    return writer


def reads(store: SqliteStore, times: range) -> dict[tuple[int, ItemId], bytes | None]:
    found = {}
    for t in times:
        for item in ITEMS:
            revision = store.read(item, t)
            found[t, item] = None if revision is None or revision.removed else revision.data
    return found


def sound(store: ReplicaStore, writer: Writer) -> None:
    for chunk in (writer.c1, writer.c2):
        assert check_chain(store, chunk) == []


@settings(max_examples=60, deadline=None)
@given(history=histories, cut=st.integers(0, 14), keep=st.none() | st.integers(1, 3))
def test_reads_at_or_after_the_horizon_are_unchanged_and_chains_check(
    history: list[list[tuple[int, bool, bool]]], cut: int, keep: int | None
) -> None:
    with tempfile.TemporaryDirectory() as folder:
        store = SqliteStore(Path(folder) / "s.sqlite", create=True)
        writer = build(store, history)
        last = len(history)
        horizon = min(cut, last)
        before = reads(store, range(horizon, last + 1))
        histories_before = {i: store.history(i) for i in ITEMS}
        links = {c: store.chain_links(c) for c in (writer.c1, writer.c2)}

        done = store.compact_history(horizon, keep)

        assert reads(store, range(horizon, last + 1)) == before
        dropped = 0
        for item, old in histories_before.items():
            now = store.history(item)
            assert now == old[len(old) - len(now) :]  # what goes is the oldest part
            if old:
                assert now[-1] == old[-1]  # the newest always stays
            if keep is not None:
                assert len(now) >= min(keep, len(old))
            dropped += len(old) - len(now)
        assert done.revisions == dropped
        assert {c: store.chain_links(c) for c in links} == links  # links never change
        sound(store, writer)
        assert store.history_floor() == (horizon if dropped else 0)
        store.close()


@pytest.fixture
def compacted(tmp_path: Path) -> tuple[SqliteStore, Writer]:
    """A store whose item 0 was written five times and item 1 twice, compacted at 4."""
    store = SqliteStore(tmp_path / "a.sqlite", create=True)
    writer = build(store, [[(0, False, False), (1, False, False)], [(0, False, False)]])
    for _ in range(2):
        build_more(writer)
    writer.commit(5, (ITEMS[1], writer.c1, b"1@5"))
    done = store.compact_history(4)
    assert (done.revisions, done.items, done.chunks) == (3, 1, 1)  # item 0 at times 1, 2, 3
    return store, writer


def build_more(writer: Writer) -> None:
    time = writer.store.clock() + 1
    writer.commit(time, (ITEMS[0], writer.c1, f"0@{time}".encode()))


@pytest.mark.parametrize("kind", ["sqlite", "memory"])
def test_a_replica_from_a_compacted_store_has_its_chain_and_goes_on_with_it(
    compacted: tuple[SqliteStore, Writer], tmp_path: Path, kind: str
) -> None:
    store, writer = compacted
    chunk = writer.c1
    assert len(store.chain_base(chunk)) == 3  # the commits at 1, 2 and 3 lost revisions
    data = StoreStates(store).take(chunk)
    other: ReplicaStore = (
        SqliteStore(tmp_path / "b.sqlite", create=True) if kind == "sqlite" else MemoryStore()
    )

    state = codec.decode_chunk_state(data)  # what a snapshot carries, as a holder installs it
    other.install_chunk(
        chunk, state.table, state.type_name, state.revisions, state.commits, [], state.compacted
    )

    assert other.chain_links(chunk) == store.chain_links(chunk)
    assert other.chain_base(chunk) == store.chain_base(chunk)
    assert check_chain(other, chunk) == []
    assert [r.data for r in other.history(ITEMS[0])] == [b"0@4"]
    # a commit after it extends both chains alike
    record = CommitRecord(CommitId.new(), 6, AUTHOR, "after", (chunk,))
    revisions = writer.revisions(record, ((ITEMS[0], chunk, b"0@6"),))
    for target in (store, other):
        target.apply_commit(record, revisions)
    assert other.chain_head(chunk) == store.chain_head(chunk)
    assert check_chain(other, chunk) == check_chain(store, chunk) == []


def test_a_changed_payload_after_the_compacted_part_is_still_found(
    compacted: tuple[SqliteStore, Writer],
) -> None:
    store, writer = compacted
    con = store._con()
    con.execute("UPDATE revisions SET data = ? WHERE data = ?", (b"1@X", b"1@5"))
    (problem,) = check_chain(store, writer.c1)
    assert "no longer matches its link" in problem


async def test_a_read_before_the_floor_is_refused_naming_gc(
    compacted: tuple[SqliteStore, Writer],
) -> None:
    store, _ = compacted
    peer = Peer(store)
    assert peer.begin(at=4).begin_time == 4
    with pytest.raises(UsageError, match="before 4: `mapctl gc` dropped that history"):
        peer.begin(at=3)


async def test_an_open_transaction_holds_the_horizon_back(tmp_path: Path) -> None:
    store = SqliteStore(tmp_path / "a.sqlite", create=True)
    build(store, [[(0, False, False)]] * 6)
    peer = Peer(store)
    reading = peer.begin(at=2)
    gc = GcOperations(peer)

    held = await gc.gc(keep_since=5)

    assert (held["horizon"], held["set_by"], held["revisions"]) == (2, "a transaction", 1)
    assert reading.begin_time == 2
    assert store.read(ITEMS[0], 2) is not None  # what it reads is still there
    reading.abort()
    done = await gc.gc(keep_since="5")
    assert (done["horizon"], done["set_by"], done["revisions"]) == (5, "asked", 3)
    with pytest.raises(UsageError, match="in memory"):
        await GcOperations(Peer.in_memory()).gc(keep=1)
