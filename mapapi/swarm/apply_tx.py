"""The holder's side of a transaction over several chunks (two-phase commit,
DESIGN §13): prepares and decisions, decided in log order on every holder.

A prepare is a proposal that names its participants. A holder validates it as
it would a one-chunk proposal; if it holds, the writes wait in the chunk's
transaction table (`Store.raft_tx_put`, state "prepared"), reserving the time
one past the chunk's clock, and nothing is visible yet. While a transaction is
prepared on a chunk, every other proposal or prepare to that chunk is refused as
busy (the writer proposes it again once the chunk is free): so no commit lands
between a prepare and its decision, the chunk's clock does not move, and the
decision's time, the largest time its chunks reserved, is past everything a
reader of any of its chunks could have begun at.

A decision is final where it is first applied: the chunk records it, writes the
prepared revisions at the decision's time (commit) or drops them (abort), and
every later decision for the same transaction only reports the first one. The
coordinator decides the first participant's log first, and so does whoever
recovers an abandoned transaction (`swarm/tx_recovery.py`), so that chunk's log
holds the transaction's one decision, and the others follow it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

from mapapi.core import codec
from mapapi.core.errors import CorruptRepoError
from mapapi.core.history import CommitRecord
from mapapi.core.ids import ChunkId, CommitId
from mapapi.core.proposal import Proposal, TimeFloor, TxDecision
from mapapi.core.validate import build_revisions
from mapapi.store.base import ReplicaStore, TxRow
from mapapi.swarm.apply import Outcome, apply_proposal, decide, write_commit
from mapapi.swarm.group_state import Applied, ApplyFn
from mapapi.swarm.raft_types import Entry

PREPARED, COMMITTED, ABORTED = "prepared", "committed", "aborted"


def applier(store: ReplicaStore) -> ApplyFn:
    """The `RaftGroups` apply hook of a peer: each committed entry is a proposal
    (`apply_proposal`), a prepare or a decision (below), decided and written on
    this replica, or a readers' floor that moves the chunk's clock; its `Outcome`
    goes to the proposer."""

    def apply_entry(chunk: ChunkId, entry: Entry) -> Applied:
        carried = codec.decode_entry(entry.data)
        if isinstance(carried, TimeFloor):
            # A prepared transaction's decision must stay past the chunk's clock: wait.
            if store.raft_tx_prepared(chunk):
                return Applied(Outcome(busy=True))
            return Applied(Outcome(), carried.time)
        if isinstance(carried, TxDecision):
            outcome = apply_decision(store, chunk, carried)
            # A chunk whose prepare only validated reads writes nothing, yet its
            # clock moves to the decision's time, as a floor would.
            decided = outcome.decision
            time = decided.time if decided is not None and decided.commit else 0
            return Applied(outcome, outcome.record.time if outcome.record else time)
        if carried.is_prepare:
            outcome = apply_prepare(store, chunk, carried)
        else:
            outcome = apply_proposal(store, chunk, carried)
        return Applied(outcome, outcome.record.time if outcome.record else 0)

    return apply_entry


SMALL_ENTRY = 1024
"""Bytes under which an entry may be a decision (weighed by what it writes)."""


def weight(store: ReplicaStore) -> Callable[[ChunkId, Entry], int]:
    """What applying an entry costs (`GroupApplier.weigh`): its size, but for a
    decision to commit, the size of the prepare it writes."""

    def weigh(chunk: ChunkId, entry: Entry) -> int:
        if len(entry.data) > SMALL_ENTRY:
            return len(entry.data)
        try:
            carried = codec.decode_entry(entry.data)
        except CorruptRepoError:
            return len(entry.data)  # applying it says so
        if isinstance(carried, TxDecision) and carried.commit:
            kept = store.raft_tx(chunk, carried.commit_id)
            return len(entry.data) + (0 if kept is None else len(kept.data))
        return len(entry.data)

    return weigh


def apply_prepare(store: ReplicaStore, chunk: ChunkId, proposal: Proposal) -> Outcome:
    """Decide one chunk's prepare of a multi-chunk transaction (see the module
    docstring); inside `store.exclusive()`, with the applied index."""
    kept = store.raft_tx(chunk, proposal.commit_id)
    if kept is not None:  # proposed again, or decided (by recovery) before it arrived
        if kept.state == PREPARED:
            return Outcome(prepared=kept.time)
        return _recorded(proposal.commit_id, kept)
    held = decide(store, chunk, proposal)
    if isinstance(held, Outcome):
        return held
    waiting = replace(proposal, changes=tuple(held.changes))
    store.raft_tx_put(
        chunk, proposal.commit_id, TxRow(PREPARED, held.time, codec.encode_entry(waiting))
    )
    return Outcome(prepared=held.time)


def apply_decision(store: ReplicaStore, chunk: ChunkId, decision: TxDecision) -> Outcome:
    """Apply a transaction's decision to `chunk` if it is the first one there;
    report the decision the chunk keeps either way."""
    kept = store.raft_tx(chunk, decision.commit_id)
    if kept is not None and kept.state != PREPARED:
        return _recorded(decision.commit_id, kept)
    if kept is None:  # never prepared here (its prepare was refused, lost or is late)
        row = TxRow(COMMITTED if decision.commit else ABORTED, decision.time)
        store.raft_tx_put(chunk, decision.commit_id, row)
        return Outcome(decision=decision)
    if not decision.commit:
        store.raft_tx_put(chunk, decision.commit_id, TxRow(ABORTED, 0))
        return Outcome(decision=decision)
    waiting = codec.decode_entry(kept.data)
    assert isinstance(waiting, Proposal)  # apply_prepare wrote it
    time = max(decision.time, kept.time)
    if not waiting.changes:  # it only validated a serializable transaction's reads here
        store.raft_tx_put(chunk, decision.commit_id, TxRow(COMMITTED, time))
        return Outcome(decision=TxDecision(decision.commit_id, True, time))
    record = CommitRecord(
        waiting.commit_id,
        time,
        waiting.author,
        waiting.message,
        waiting.participants,
        waiting.author_name,
        waiting.view,
    )
    latest = store.latest([c.item_id for c in waiting.changes])
    revisions = build_revisions(waiting.changes, latest, time, waiting.author, record.id)
    write_commit(store, chunk, record, revisions)
    store.raft_tx_put(chunk, decision.commit_id, TxRow(COMMITTED, time))
    return Outcome(record, tuple(revisions), decision=TxDecision(record.id, True, time))


def _recorded(commit_id: CommitId, kept: TxRow) -> Outcome:
    """The decision a chunk keeps for a transaction it decided already."""
    return Outcome(decision=TxDecision(commit_id, kept.state == COMMITTED, kept.time))
