"""The holder's side of a commit through a chunk's Raft group (DESIGN §13).

A committed log entry carries a `Proposal`; every holder decides it here, in log
order, on its own replica of the chunk. The decision depends only on the
replica (identical on every holder at the same log index) and the proposal, so
all holders decide alike without talking: validation is the same pure
`validate` as a lone peer's commit, with no auto-merge hook (merge policies are
Python objects of one peer; the writer merges and proposes again), and the
commit rules the application gave at construction (every holder runs the same
application).

Each commit extends the chunk's hash chain (`core/chain.py`) in the same
transaction, so holders that applied the same log hold the same head, and a
store changed behind their back no longer matches its chain (`chain_check`).

The commit's time is the proposal's Lamport time, raised to one past the
chunk's clock (including commits applied earlier in the same batch) when a
proposal from before a leader change arrives with an older time: revision times
then grow in log order, which validation relies on.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from mapapi.core import chain, codec
from mapapi.core.errors import UsageError
from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, ItemId
from mapapi.core.proposal import Proposal
from mapapi.core.transaction import Conflict
from mapapi.core.validate import build_revisions, validate
from mapapi.core.view import Scope
from mapapi.store.base import ReplicaStore, Store
from mapapi.swarm.commit_check import CommitRule
from mapapi.swarm.groups import Applied, ApplyFn
from mapapi.swarm.raft_types import Entry


@dataclass(frozen=True, slots=True)
class Outcome:
    """How a holder decided a proposal: committed (`record`), conflicting
    (`conflicts`) or refused by a rule (`refusal`); the same on every holder."""

    record: CommitRecord | None = None
    revisions: tuple[Revision, ...] = ()
    conflicts: tuple[Conflict, ...] = ()
    refusal: str = ""

    @property
    def committed(self) -> bool:
        """Whether the proposal's changes were written."""
        return self.record is not None


def apply_proposal(
    store: ReplicaStore,
    chunk: ChunkId,
    proposal: Proposal,
    rules: Sequence[CommitRule] = (),
) -> Outcome:
    """Decide `proposal` on this replica of `chunk` and write it if it holds.

    Call inside `store.exclusive()`, with the entry's applied index recorded in
    the same transaction (`RaftGroups` does), so the effect lands exactly once.
    The chunk's clock (`Store.raft_time`) is the caller's to advance to
    `Outcome.record.time`.
    """
    # Only this chunk's part of the reads and scans: a holder may hold other chunks
    # too, and a decision that looked at them would differ from holder to holder.
    scopes = {(table, chunk) for table, scope in proposal.scopes if scope in (None, chunk)}
    reads = read_ids(store, proposal.isolation, proposal.read_set, scopes, proposal.begin_time)
    latest = store.latest([c.item_id for c in proposal.changes] + sorted(reads))
    reads = {i for i in reads if i in latest and latest[i].chunk_id == chunk}
    accepted, conflicts = validate(
        proposal.changes,
        latest,
        proposal.since_of,
        read_set=reads,
        base_of=lambda item_id: store.read(item_id, proposal.begin_time),
    )
    if conflicts:
        return Outcome(conflicts=tuple(conflicts))
    try:
        for rule in rules:
            rule.check(store, accepted)
    except UsageError as exc:
        return Outcome(refusal=str(exc))
    if not accepted:
        return Outcome()
    time = max(proposal.time, chunk_clock(store, chunk) + 1)
    record = CommitRecord(
        proposal.commit_id,
        time,
        proposal.author,
        proposal.message,
        (chunk,),
        proposal.author_name,
        proposal.view,
    )
    revisions = build_revisions(accepted, latest, time, proposal.author, record.id)
    store.apply_commit(record, revisions)
    previous = store.chain_head(chunk) or chain.GENESIS
    store.chain_link(chunk, record.id, chain.link(previous, chunk, record, revisions))
    return Outcome(record, tuple(revisions))


def chunk_clock(store: ReplicaStore, chunk: ChunkId) -> int:
    """The newest commit time in the chunk's replica: its recorded clock, or a later
    commit applied earlier in the same transaction (`RaftGroups` records the clock
    once per batch of entries, after them all)."""
    clock = store.raft_time(chunk)
    written = store.changed_since(clock, chunk=chunk)
    return max((r.update_time for r in written), default=clock)


def applier(store: ReplicaStore, rules: Sequence[CommitRule] = ()) -> ApplyFn:
    """The `RaftGroups` apply hook of a peer: each committed entry is a proposal,
    decided and written by `apply_proposal`; its outcome goes to the proposer."""

    def apply_entry(chunk: ChunkId, entry: Entry) -> Applied:
        outcome = apply_proposal(store, chunk, codec.decode_proposal(entry.data), rules)
        return Applied(outcome, outcome.record.time if outcome.record else 0)

    return apply_entry


def read_ids(
    store: Store,
    isolation: str,
    read_set: Iterable[ItemId],
    scopes: Iterable[Scope],
    begin_time: int,
) -> set[ItemId]:
    """The items a serializable transaction must find unchanged since `begin_time`:
    those it read and those written since in the scopes it scanned (phantoms)."""
    if isolation != "serializable":
        return set()
    found = set(read_set)
    for table, scope in scopes:
        found |= {r.item_id for r in store.changed_since(begin_time, table=table, chunk=scope)}
    return found
