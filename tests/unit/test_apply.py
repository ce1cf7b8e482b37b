"""Deciding a proposal on a replica (swarm/apply.py): the same on every holder."""

from __future__ import annotations

from collections.abc import Sequence

import pytest

from mapapi.core import codec
from mapapi.core.errors import UsageError
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId
from mapapi.core.proposal import Proposal
from mapapi.core.transaction import Change, Op
from mapapi.store.base import Store
from mapapi.store.memory import MemoryStore
from mapapi.swarm.apply import Outcome, apply_proposal
from mapapi.swarm.commit_check import CommitRule

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


def decide(store: MemoryStore, p: Proposal, rules: Sequence[CommitRule] = ()) -> Outcome:
    with store.exclusive():
        outcome = apply_proposal(store, CHUNK, p, rules)
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


class Refuse:
    """A commit rule that refuses everything."""

    def check(self, store: Store, changes: Sequence[Change]) -> None:
        raise UsageError("refused by the rule")


def test_a_refusing_rule_writes_nothing(store: MemoryStore) -> None:
    outcome = decide(store, proposal(Op.INSERT, b"0", begin=0, time=1), [Refuse()])
    assert outcome.refusal == "refused by the rule"
    assert store.latest([ITEM]) == {}


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
    assert codec.decode_proposal(codec.encode_proposal(original)) == original
