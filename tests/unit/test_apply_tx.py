"""Prepares and decisions of multi-chunk transactions on a replica (swarm/apply_tx.py),
through the same apply hook the Raft groups use, on a memory and an SQLite store."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from mapapi.core import codec
from mapapi.core.change import Change, Op
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId
from mapapi.core.proposal import LogEntry, Proposal, TimeFloor, TxDecision
from mapapi.store.base import ReplicaStore
from mapapi.store.memory import MemoryStore
from mapapi.store.sqlite import SqliteStore
from mapapi.swarm.apply import Outcome
from mapapi.swarm.apply_tx import applier
from mapapi.swarm.chain_check import check_chain
from mapapi.swarm.raft_types import Entry, EntryKind

A, B = sorted([ChunkId.new(), ChunkId.new()])
X, Y = ItemId.new(), ItemId.new()  # X in A, Y in B
AUTHOR = PeerId.new()


@pytest.fixture(params=["memory", "sqlite"])
def store(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[ReplicaStore]:
    made: ReplicaStore = (
        MemoryStore() if request.param == "memory" else SqliteStore(tmp_path / "s", create=True)
    )
    made.add_table("t", "google.protobuf.Struct")
    for chunk in (A, B):
        made.add_chunk(chunk, "t")
        made.raft_save(chunk, hard=(1, 0, 0))
    yield made
    made.close()


class Log:
    """Applies entries to one store as a chunk's log would, index after index."""

    def __init__(self, store: ReplicaStore) -> None:
        self.store = store
        self.apply = applier(store)
        self.index: dict[ChunkId, int] = {A: 0, B: 0}

    def __call__(self, chunk: ChunkId, carried: LogEntry) -> Outcome:
        self.index[chunk] += 1
        entry = Entry(1, self.index[chunk], EntryKind.NORMAL, codec.encode_entry(carried))
        with self.store.exclusive():
            applied = self.apply(chunk, entry)
            self.store.raft_applied(chunk, self.index[chunk], applied.time)
        assert isinstance(applied.result, Outcome)
        return applied.result


def write(item: ItemId, chunk: ChunkId, data: bytes, op: Op = Op.INSERT) -> Change:
    return Change(op, "t", item, chunk, data)


def single(change: Change, begin: int, time: int) -> Proposal:
    return Proposal(CommitId.new(), time, AUTHOR, "r", "", "m", begin, "snapshot", (change,))


def prepares(
    begin: int, time: int, x: bytes = b"x1", y: bytes = b"y1", op: Op = Op.INSERT
) -> dict[ChunkId, Proposal]:
    """The prepares of one transaction writing X in A and Y in B."""
    cid = CommitId.new()
    return {
        c: Proposal(
            cid, time, AUTHOR, "r", "", "both", begin, "snapshot", (change,), participants=(A, B)
        )
        for c, change in ((A, write(X, A, x, op)), (B, write(Y, B, y)))
    }


def test_a_prepare_reserves_a_time_and_shows_nothing_until_committed(
    store: ReplicaStore,
) -> None:
    log = Log(store)
    log(A, single(write(X, A, b"x0"), 0, 5))
    p = prepares(begin=5, time=3, x=b"x1", op=Op.UPDATE)
    held = log(A, p[A])
    assert held.prepared == 6  # one past the chunk's clock, above the proposer's time
    assert store.latest([X])[X].data == b"x0"
    assert store.raft_time(A) == 5  # the clock waits for the decision
    done = log(A, TxDecision(p[A].commit_id, True, 9))
    assert done.record is not None
    assert done.record.chunks == (A, B)
    assert store.latest([X])[X].data == b"x1"
    assert store.latest([X])[X].update_time == 9
    assert store.raft_time(A) == 9
    assert check_chain(store, A) == []
    assert store.raft_tx_prepared(A) == []


def test_a_prepared_chunk_holds_back_every_other_writer_until_the_decision(
    store: ReplicaStore,
) -> None:
    log = Log(store)
    p = prepares(begin=0, time=1)
    other = prepares(begin=0, time=1, x=b"x2")
    assert log(A, p[A]).prepared
    assert log(A, single(write(ItemId.new(), A, b"z"), 0, 2)).busy
    assert log(A, other[A]).busy
    assert log(A, p[A]).prepared  # the same prepare again changes nothing
    log(A, TxDecision(p[A].commit_id, False))
    assert store.latest([X]) == {}  # aborted: nothing written
    assert log(A, single(write(ItemId.new(), A, b"z"), 0, 2)).committed


def test_the_first_decision_is_final(store: ReplicaStore) -> None:
    log = Log(store)
    p = prepares(begin=0, time=1)
    log(A, p[A])
    assert log(A, TxDecision(p[A].commit_id, False)).decision == TxDecision(p[A].commit_id, False)
    late = log(A, TxDecision(p[A].commit_id, True, 4))
    assert late.decision is not None
    assert not late.decision.commit
    assert late.record is None
    assert store.latest([X]) == {}


def test_a_prepare_after_its_abort_stays_aborted(store: ReplicaStore) -> None:
    """Recovery may abort on a chunk whose prepare is still on its way."""
    log = Log(store)
    p = prepares(begin=0, time=1)
    log(B, TxDecision(p[B].commit_id, False))
    late = log(B, p[B])
    assert not late.prepared
    assert late.decision is not None
    assert not late.decision.commit
    assert store.raft_tx_prepared(B) == []


def test_a_conflicting_prepare_holds_nothing(store: ReplicaStore) -> None:
    log = Log(store)
    log(A, single(write(X, A, b"x0"), 0, 1))
    stale = prepares(begin=0, time=2)  # began before X existed, and inserts it
    outcome = log(A, stale[A])
    assert [c.item_id for c in outcome.conflicts] == [X]
    assert store.raft_tx_prepared(A) == []
    assert log(A, single(write(ItemId.new(), A, b"z"), 1, 2)).committed


def test_both_chunks_commit_at_one_time(store: ReplicaStore) -> None:
    """A holder of both chunks ends with one record and both revisions at the decision's time."""
    log = Log(store)
    log(B, single(write(ItemId.new(), B, b"b"), 0, 7))
    p = prepares(begin=0, time=1)
    t = max(log(A, p[A]).prepared, log(B, p[B]).prepared)
    assert t == 8
    for chunk in (A, B):
        log(chunk, TxDecision(p[A].commit_id, True, t))
    record = store.commit_record(p[A].commit_id)
    assert record is not None
    assert record.time == t
    assert {r.item_id: r.update_time for r in store.commit_revisions(record.id)} == {X: t, Y: t}


def test_a_floor_moves_the_clock_so_later_commits_are_stamped_past_it(
    store: ReplicaStore,
) -> None:
    log = Log(store)
    log(A, TimeFloor(50))
    assert store.raft_time(A) == 50
    later = log(A, single(write(X, A, b"x"), 0, 3))  # a writer whose clock is far behind
    assert later.record is not None
    assert later.record.time == 51


def test_a_floor_waits_while_a_transaction_is_prepared(store: ReplicaStore) -> None:
    log = Log(store)
    p = prepares(begin=0, time=1)
    log(A, p[A])
    assert log(A, TimeFloor(50)).busy
    assert store.raft_time(A) == 0  # the decision's time stays past the clock


def test_a_prepare_that_only_validates_reads_holds_the_chunk_and_writes_nothing(
    store: ReplicaStore,
) -> None:
    log = Log(store)
    log(B, single(write(Y, B, b"y0"), 0, 4))
    read_only = Proposal(
        CommitId.new(), 5, AUTHOR, "r", "", "reads Y", 4, "serializable", (),
        read_set=frozenset({Y}), participants=(A, B),
    )  # fmt: skip
    held = log(B, read_only)
    assert held.prepared == 5
    assert log(B, single(write(Y, B, b"y1", Op.UPDATE), 4, 6)).busy  # no write on what it read
    done = log(B, TxDecision(read_only.commit_id, True, 8))
    assert done.record is None
    assert done.decision == TxDecision(read_only.commit_id, True, 8)
    assert store.latest([Y])[Y].data == b"y0"
    assert store.raft_time(B) == 8  # later writes are stamped past the transaction
    assert check_chain(store, B) == []


def test_a_read_it_validates_that_changed_is_a_conflict(store: ReplicaStore) -> None:
    log = Log(store)
    log(B, single(write(Y, B, b"y0"), 0, 4))
    log(B, single(write(Y, B, b"y1", Op.UPDATE), 4, 6))
    stale = Proposal(
        CommitId.new(), 7, AUTHOR, "r", "", "read Y at 4", 4, "serializable", (),
        read_set=frozenset({Y}), participants=(A, B),
    )  # fmt: skip
    refused = log(B, stale)
    assert [c.item_id for c in refused.conflicts] == [Y]
    assert not refused.prepared
