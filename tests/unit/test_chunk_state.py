"""A chunk's state out of one store and into another (swarm/chunk_state.py), as a Raft
snapshot carries it: history, clock, hash chain and transaction records alike."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from mapapi.core.change import Change, Op
from mapapi.core.errors import CorruptRepoError
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId
from mapapi.core.proposal import Proposal, TxDecision
from mapapi.store.base import ReplicaStore
from mapapi.store.memory import MemoryStore
from mapapi.store.sqlite import SqliteStore
from mapapi.swarm.apply import apply_proposal
from mapapi.swarm.apply_tx import apply_decision, apply_prepare
from mapapi.swarm.chunk_state import StoreStates

A, B = sorted([ChunkId.new(), ChunkId.new()])
AUTHOR = PeerId.new()


def make(kind: str, path: Path) -> ReplicaStore:
    store: ReplicaStore = MemoryStore() if kind == "memory" else SqliteStore(path, create=True)
    store.raft_save(A, hard=(1, 0, 0))
    return store


@pytest.fixture(params=["memory", "sqlite"])
def pair(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[tuple[ReplicaStore, ...]]:
    made = tuple(make(request.param, tmp_path / name) for name in ("from", "to"))
    made[0].add_table("t", "google.protobuf.Struct")
    made[0].add_chunk(A, "t")
    yield made
    for store in made:
        store.close()


def proposal(data: bytes, time: int, participants: tuple[ChunkId, ...] = ()) -> Proposal:
    change = Change(Op.INSERT, "t", ItemId.new(), A, data)
    return Proposal(
        CommitId.new(),
        time,
        AUTHOR,
        "r",
        "",
        "m",
        0,
        "snapshot",
        (change,),
        {},
        participants=participants,
    )


def test_a_replica_installed_from_a_snapshot_is_the_senders(
    pair: tuple[ReplicaStore, ReplicaStore],
) -> None:
    sender, receiver = pair
    with sender.exclusive():
        for i in range(3):
            apply_proposal(sender, A, proposal(str(i).encode(), i + 1))
        aborted = proposal(b"gone", 9, (A, B))
        apply_prepare(sender, A, aborted)
        apply_decision(sender, A, TxDecision(aborted.commit_id, False))
        held = proposal(b"waits", 10, (A, B))
        apply_prepare(sender, A, held)  # still prepared: the chunk is held
        sender.raft_applied(A, 5, 3)
    StoreStates(receiver).install(A, StoreStates(sender).take(A), 5)
    assert receiver.chunk_commits(A) == sender.chunk_commits(A)
    assert receiver.chunk_revisions(A) == sender.chunk_revisions(A)
    assert receiver.chain_links(A) == sender.chain_links(A)
    assert receiver.raft_txs(A) == sender.raft_txs(A)
    assert [c for c, _ in receiver.raft_tx_prepared(A)] == [held.commit_id]
    kept = receiver.raft_load(A)
    assert kept is not None
    assert (kept.applied, kept.time) == (5, 3)


def test_a_damaged_snapshot_is_refused_and_changes_nothing(
    pair: tuple[ReplicaStore, ReplicaStore],
) -> None:
    _, receiver = pair
    with pytest.raises(CorruptRepoError, match="snapshot does not parse"):
        StoreStates(receiver).install(A, b"\xff\x00garbage", 5)
    assert receiver.chunks() == []
