"""The two-phase commit coordinator (swarm/two_phase.py), pure: what it proposes next
for every way a chunk can answer."""

from __future__ import annotations

import pytest

from mapapi.core.change import Change, Conflict, Op
from mapapi.core.history import Revision
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId
from mapapi.core.proposal import Proposal, TxDecision
from mapapi.swarm.two_phase import Answer, TwoPhase

A, B, C = sorted(ChunkId.new() for _ in range(3))
CID = CommitId.new()


def machine(*chunks: ChunkId) -> TwoPhase:
    def prepare(chunk: ChunkId) -> Proposal:
        change = Change(Op.INSERT, "t", ItemId.new(), chunk, b"x")
        return Proposal(
            CID, 1, PeerId.new(), "r", "", "m", 0, "snapshot", (change,), {}, participants=chunks
        )

    return TwoPhase({c: prepare(c) for c in chunks})


def commit(time: int) -> TxDecision:
    return TxDecision(CID, True, time)


ABORT = TxDecision(CID, False)


def conflict(chunk: ChunkId) -> Conflict:
    item = ItemId.new()
    theirs = Revision(item, "t", chunk, b"y", 1, 1, False, PeerId.new(), CommitId.new())
    return Conflict("t", item, chunk, None, None, theirs)


def test_prepares_go_in_chunk_order_then_the_first_chunk_decides_then_the_rest() -> None:
    m = machine(A, B, C)
    assert [c for c, _ in m.start()] == [A]
    assert [c for c, _ in m.answered(A, Answer(prepared=4))] == [B]
    assert [c for c, _ in m.answered(B, Answer(prepared=9))] == [C]
    assert m.answered(C, Answer(prepared=6)) == [(A, commit(9))]  # the largest reserved time
    assert sorted(m.answered(A, Answer(decision=commit(9)))) == sorted(
        [(B, commit(9)), (C, commit(9))]
    )
    assert not m.done
    m.answered(B, Answer(decision=commit(9)))
    m.answered(C, Answer(unknown="chunk c: timed out"))  # its leader recovers it later
    assert m.done
    assert m.committed
    assert m.aborted_why == ""


def test_a_conflict_on_a_later_chunk_aborts_the_prepared_ones() -> None:
    m = machine(A, B, C)
    m.start()
    m.answered(A, Answer(prepared=2))
    assert m.answered(B, Answer(conflicts=(conflict(B),))) == [(A, ABORT)]
    assert m.answered(A, Answer(decision=ABORT)) == [(B, ABORT)]  # B may hold nothing: harmless
    m.answered(B, Answer(decision=ABORT))
    assert m.done
    assert not m.committed
    assert m.conflicts
    assert m.aborted_why == "1 conflict(s)"


def test_a_prepare_of_unknown_fate_is_aborted_even_on_the_first_chunk() -> None:
    m = machine(A, B)
    m.start()
    assert m.answered(A, Answer(unknown="timed out")) == [(A, ABORT)]
    assert m.answered(A, Answer(decision=ABORT)) == []
    assert m.done
    assert not m.committed
    assert m.failed == "timed out"


def test_a_recovery_abort_on_the_first_chunk_wins_over_the_commit() -> None:
    m = machine(A, B)
    m.start()
    m.answered(A, Answer(prepared=2))
    assert m.answered(B, Answer(prepared=3)) == [(A, commit(3))]
    assert m.answered(A, Answer(decision=ABORT)) == [(B, ABORT)]
    m.answered(B, Answer(decision=ABORT))
    assert m.done
    assert not m.committed
    assert "recovering" in m.aborted_why


def test_an_unknown_first_decision_leaves_the_outcome_uncertain() -> None:
    m = machine(A, B)
    m.start()
    m.answered(A, Answer(prepared=2))
    m.answered(B, Answer(prepared=3))
    assert m.answered(A, Answer(unknown="no leader")) == []
    assert m.done
    assert m.decision is None
    assert m.uncertain == "no leader"


def test_prepares_must_name_every_participant_in_order() -> None:
    with pytest.raises(ValueError, match="in order"):
        TwoPhase({B: machine(A, B).prepares[B], A: machine(A, B).prepares[A]})
