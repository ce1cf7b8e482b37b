"""What applying a chunk's log entry costs (`apply_tx.weight`), which decides whether
it is applied on the event loop or in a worker (`swarm/group_apply.py`): a decision
to commit is a tiny entry that writes every row its transaction prepared."""

from __future__ import annotations

from mapapi.core import codec
from mapapi.core.ids import ChunkId, CommitId
from mapapi.core.proposal import TimeFloor, TxDecision
from mapapi.store.base import TxRow
from mapapi.store.memory import MemoryStore
from mapapi.swarm.apply_tx import weight
from mapapi.swarm.group_apply import HEAVY_BYTES
from mapapi.swarm.raft_types import Entry, EntryKind

CHUNK = ChunkId.new()


def entry(data: bytes) -> Entry:
    return Entry(3, 1, EntryKind.NORMAL, data)


def test_a_decision_to_commit_weighs_what_it_prepared() -> None:
    store = MemoryStore()
    commit = CommitId.new()
    store.raft_tx_put(CHUNK, commit, TxRow("prepared", 7, b"r" * (2 * HEAVY_BYTES)))
    decision = entry(codec.encode_entry(TxDecision(commit, True, 7)))

    assert weight(store)(CHUNK, decision) > HEAVY_BYTES
    assert len(decision.data) < 100


def test_an_abort_a_floor_and_an_unknown_decision_weigh_their_size() -> None:
    store = MemoryStore()
    commit = CommitId.new()
    store.raft_tx_put(CHUNK, commit, TxRow("prepared", 7, b"r" * (2 * HEAVY_BYTES)))
    weigh = weight(store)
    for carried in (
        TxDecision(commit, False, 0),
        TimeFloor(9),
        TxDecision(CommitId.new(), True, 7),
    ):
        small = entry(codec.encode_entry(carried))
        assert weigh(CHUNK, small) == len(small.data)


def test_a_big_or_unreadable_entry_weighs_its_size() -> None:
    weigh = weight(MemoryStore())
    assert weigh(CHUNK, entry(b"x" * 5000)) == 5000
    assert weigh(CHUNK, entry(b"\xff\x00")) == 2
