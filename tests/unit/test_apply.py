"""Deciding a proposal on a replica (swarm/apply.py): the same on every holder."""

from __future__ import annotations

import sqlite3
from dataclasses import replace
from pathlib import Path

import pytest

from mapapi.core import codec
from mapapi.core.change import Change, Op
from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId
from mapapi.core.proposal import Proposal
from mapapi.core.transaction import Isolation
from mapapi.store.memory import MemoryStore
from mapapi.store.sqlite import SqliteStore
from mapapi.swarm.apply import Outcome, apply_proposal
from mapapi.swarm.chain_check import check_chain

CHUNK = ChunkId.new()
ITEM = ItemId.new()
AUTHOR = PeerId.new()


def proposal(op: Op, data: bytes, begin: int, time: int, item: ItemId = ITEM) -> Proposal:
    change = Change(op, "t", item, CHUNK, data)
    return Proposal(CommitId.new(), time, AUTHOR, "robot", "", "m", begin, "snapshot", (change,))


@pytest.fixture
def store() -> MemoryStore:
    made = MemoryStore()
    made.add_table("t", "google.protobuf.Struct")
    made.add_chunk(CHUNK, "t")
    made.raft_save(CHUNK, hard=(1, 0, 1))
    return made


def decide(store: MemoryStore, p: Proposal) -> Outcome:
    with store.exclusive():
        outcome = apply_proposal(store, CHUNK, p)
        if outcome.record is not None:
            store.raft_applied(CHUNK, store.raft_time(CHUNK) + 1, outcome.record.time)
    return outcome


def test_the_first_of_two_racing_updates_commits_and_the_second_conflicts(
    store: MemoryStore,
) -> None:
    decide(store, proposal(Op.INSERT, b"0", begin=0, time=1))
    first = decide(store, proposal(Op.UPDATE, b"1", begin=1, time=2))
    second = decide(store, proposal(Op.UPDATE, b"2", begin=1, time=3))
    assert first.committed
    assert [c.item_id for c in second.conflicts] == [ITEM]
    latest = store.latest([ITEM])[ITEM]
    assert latest.data == b"1"


def test_an_older_proposal_time_is_raised_past_the_chunks_clock(store: MemoryStore) -> None:
    decide(store, proposal(Op.INSERT, b"0", begin=0, time=10))
    late = decide(store, proposal(Op.UPDATE, b"1", begin=10, time=4))  # from a former leader
    assert late.record is not None
    assert late.record.time == 11
    assert store.latest([ITEM])[ITEM].update_time == 11


def test_a_proposal_survives_the_log_byte_for_byte() -> None:
    original = Proposal(
        CommitId.new(),
        7,
        AUTHOR,
        "robot",
        "bob",
        "move",
        5,
        "serializable",
        (Change(Op.UPDATE, "t", ITEM, CHUNK, b"x"),),
        {ITEM: 6},
        frozenset({ItemId.new()}),
        frozenset({("t", CHUNK), ("u", None)}),
    )
    assert codec.decode_entry(codec.encode_entry(original)) == original


def test_the_second_proposal_of_one_batch_is_stamped_after_the_first(store: MemoryStore) -> None:
    """Simulator, commit path, every seed: `RaftGroups` records the chunk's clock once per
    batch of entries, after them all, so the second proposal of a batch was stamped from the
    stale clock, at or before the first (times 4 then 4, or 4 then 2): revision times did
    not grow in log order, and a read at the first's time saw the second's write."""
    other = ItemId.new()
    with store.exclusive():
        first = apply_proposal(store, CHUNK, proposal(Op.INSERT, b"0", begin=0, time=4))
        second = apply_proposal(
            store, CHUNK, proposal(Op.INSERT, b"1", begin=0, time=2, item=other)
        )
        assert first.record is not None
        assert second.record is not None
        store.raft_applied(CHUNK, 2, max(first.record.time, second.record.time))
    assert second.record.time == 5
    assert store.read(other, 4) is None
    assert store.raft_time(CHUNK) == 5


def withdrawal(
    isolation: Isolation, begin: int, src: ItemId, left: int, joint: frozenset[ItemId]
) -> Proposal:
    """Take money from `src` (leaving `left`), having read every account of `joint`."""
    change = Change(Op.UPDATE, "t", src, CHUNK, str(left).encode())
    return Proposal(
        CommitId.new(),
        begin + 1,
        AUTHOR,
        "robot",
        "",
        "m",
        begin,
        isolation,
        (change,),
        read_set=joint,
    )


@pytest.mark.parametrize(("isolation", "skewed"), [("snapshot", True), ("serializable", False)])
def test_write_skew_breaks_a_joint_balance_only_under_snapshot_isolation(
    store: MemoryStore, isolation: Isolation, skewed: bool
) -> None:
    """Two withdrawals of 80 from a couple's accounts (50 each), each allowed because the
    two together hold 100, each from a different account: disjoint writes, so snapshot
    isolation commits both and the couple owes 60; serializable (the read set) refuses the
    second. The bank transfers of the simulator run serializable for this reason."""
    a, b = ItemId.new(), ItemId.new()
    for item in (a, b):
        decide(store, proposal(Op.INSERT, b"50", begin=0, time=1, item=item))
    joint = frozenset({a, b}) if isolation == "serializable" else frozenset()
    begin = store.raft_time(CHUNK)  # both read a = b = 50 here
    first = decide(store, withdrawal(isolation, begin, a, -30, joint))
    second = decide(store, withdrawal(isolation, begin, b, -30, joint))
    assert first.committed
    assert second.committed is skewed
    latest = store.latest([a, b])
    total = sum(int(r.data) for r in latest.values())
    assert (total < 0) is skewed


def test_every_commit_extends_the_chunks_chain_and_a_changed_payload_is_found(
    store: MemoryStore,
) -> None:
    decide(store, proposal(Op.INSERT, b"0", begin=0, time=1))
    decide(store, proposal(Op.UPDATE, b"1", begin=1, time=2))
    assert len(store.chain_links(CHUNK)) == 2
    assert check_chain(store, CHUNK) == []
    # a byte flipped on disk: the revision of the first commit changes behind the chain
    first = store.chain_links(CHUNK)[0][0]
    (revision,) = store.commit_revisions(first)
    store.drop_chunk(CHUNK)
    store.add_chunk(CHUNK, "t")
    record = store.commit_record(first)
    assert record is not None
    store.apply_commit(record, [replace(revision, data=b"\x01")])
    assert any("no longer matches" in p for p in check_chain(store, CHUNK))


def test_a_byte_flipped_in_the_sqlite_file_is_found(tmp_path: Path) -> None:
    path = tmp_path / "s.sqlite"
    sq = SqliteStore(path, create=True)
    sq.add_table("t", "google.protobuf.Struct")
    sq.add_chunk(CHUNK, "t")
    sq.raft_save(CHUNK, hard=(1, 0, 1))
    for p in (proposal(Op.INSERT, b"0", 0, 1), proposal(Op.UPDATE, b"1", 1, 2)):
        with sq.exclusive():
            apply_proposal(sq, CHUNK, p)
    assert check_chain(sq, CHUNK) == []
    sq.close()
    con = sqlite3.connect(path)
    con.execute("UPDATE revisions SET data = x'01' WHERE update_time = 1")
    con.commit()
    con.close()
    again = SqliteStore(path)
    problems = check_chain(again, CHUNK)
    again.close()
    assert len(problems) == 1
    assert "no longer matches" in problems[0]


def test_holders_decide_alike_whatever_other_chunks_they_hold(store: MemoryStore) -> None:
    """A serializable proposal that read an item of another chunk and scanned a whole table
    was decided against whatever else each holder held: where the other chunk's item had
    changed since the begin time, a conflict; on a holder without that chunk, a commit. Two
    histories of one chunk. Each group now decides only its chunk's part."""
    other_chunk, elsewhere = ChunkId.new(), ItemId.new()
    both = MemoryStore()
    both.add_table("t", "google.protobuf.Struct")
    for chunk in (CHUNK, other_chunk):
        both.add_chunk(chunk, "t")
    both.raft_save(CHUNK, hard=(1, 0, 1))
    record = CommitRecord(CommitId.new(), 5, AUTHOR, "m", (other_chunk,))
    written = Revision(elsewhere, "t", other_chunk, b"1", 5, 5, False, AUTHOR, record.id)
    both.apply_commit(record, [written])
    change = Change(Op.INSERT, "t", ITEM, CHUNK, b"0")
    scan = Proposal(
        CommitId.new(), 4, AUTHOR, "robot", "", "m", 3, "serializable", (change,),
        read_set=frozenset({elsewhere}), scopes=frozenset({("t", None)}),
    )  # fmt: skip
    outcomes = [decide(s, scan) for s in (store, both)]
    assert [o.committed for o in outcomes] == [True, True]
