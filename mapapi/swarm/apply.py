"""The holder's side of a commit through a chunk's Raft group (DESIGN §13).

A committed log entry carries a `Proposal`; every holder decides it here, in log
order, on its own replica of the chunk. The decision depends only on the
replica of the chunk (identical on every holder at the same log index) and the
proposal, so all holders decide alike without talking: validation is the same
pure `validate` as a lone peer's commit, with no auto-merge hook (merge policies
are Python objects of one peer; the writer merges and proposes again). The
application's commit rules are not checked here: they read other chunks too
(an edge's ends are vertices of another table), which a holder of this one need
not hold, so the writer checks them over the whole transaction
(`swarm/log_commit.py`).

Each commit extends the chunk's hash chain (`core/chain.py`) in the same
transaction (`Store.apply_commit` links every commit, whichever path applies
it), so holders that applied the same log hold the same head, and a store
changed behind their back no longer matches its chain (`chain_check`).

The commit's time is the proposal's Lamport time, raised to one past the
chunk's clock (including commits applied earlier in the same batch) when a
proposal from before a leader change arrives with an older time: revision times
then grow in log order, which validation relies on.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from mapapi.core.change import Change, Conflict
from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, ItemId
from mapapi.core.proposal import Proposal, TxDecision
from mapapi.core.validate import build_revisions, validate
from mapapi.core.view import Scope
from mapapi.store.base import ReplicaStore, Store


@dataclass(frozen=True, slots=True)
class Outcome:
    """How a holder decided a log entry, the same on every holder: committed
    (`record`), conflicting (`conflicts`), held back because another transaction
    is prepared on the chunk (`busy`), a
    prepare that holds (`prepared`: the time it reserved), or the decision the
    chunk keeps for a multi-chunk transaction (`decision`, `swarm/apply_tx.py`)."""

    record: CommitRecord | None = None
    revisions: tuple[Revision, ...] = ()
    conflicts: tuple[Conflict, ...] = ()
    busy: bool = False
    prepared: int = 0
    decision: TxDecision | None = None

    @property
    def committed(self) -> bool:
        """Whether the proposal's changes were written."""
        return self.record is not None


def apply_proposal(store: ReplicaStore, chunk: ChunkId, proposal: Proposal) -> Outcome:
    """Decide `proposal` on this replica of `chunk` and write it if it holds.

    Call inside `store.exclusive()`, with the entry's applied index recorded in
    the same transaction (`RaftGroups` does), so the effect lands exactly once.
    The chunk's clock (`Store.raft_time`) is the caller's to advance to
    `Outcome.record.time`.
    """
    held = decide(store, chunk, proposal)
    if isinstance(held, Outcome):
        return held
    record = CommitRecord(
        proposal.commit_id,
        held.time,
        proposal.author,
        proposal.message,
        (chunk,),
        proposal.author_name,
        proposal.view,
    )
    revisions = build_revisions(held.changes, held.latest, held.time, proposal.author, record.id)
    write_commit(store, chunk, record, revisions)
    return Outcome(record, tuple(revisions))


@dataclass(frozen=True, slots=True)
class Held:
    """A proposal that holds on a replica: the changes to write, the newest
    revisions of their items, and the time the commit gets (one past the chunk's
    clock, or the proposer's time if later)."""

    changes: list[Change]
    latest: dict[ItemId, Revision]
    time: int


def decide(store: ReplicaStore, chunk: ChunkId, proposal: Proposal) -> Outcome | Held:
    """Validate `proposal` on this replica of `chunk`: `Held` if it holds and
    writes something (or is a prepare: one that only validates a serializable
    transaction's reads here holds the chunk too), else the `Outcome` to answer
    (busy: another transaction is prepared on the chunk, `swarm/apply_tx.py`;
    conflicts; nothing to write)."""
    if any(cid != proposal.commit_id for cid, _ in store.raft_tx_prepared(chunk)):
        return Outcome(busy=True)
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
        base_of=lambda item_id: store.read(item_id, proposal.since_of(item_id)),
    )
    if conflicts:
        return Outcome(conflicts=tuple(conflicts))
    if not accepted and not proposal.is_prepare:
        return Outcome()
    return Held(accepted, latest, max(proposal.time, chunk_clock(store, chunk) + 1))


def early_conflicts(store: ReplicaStore, chunk: ChunkId, entry: object) -> tuple[Conflict, ...]:
    """The conflicts a chunk's leader answers before appending `entry` (issue 13 §3):
    those its applied replica shows already. Conflicts only grow as entries apply
    (an item's newest revision only gets newer), so every holder would decide the
    entry so too, and the loser learns it without a round of the log. Anything
    else (a prepare, a chunk held by one, a proposal that holds) is decided at apply."""
    if not isinstance(entry, Proposal) or entry.is_prepare:
        return ()
    decided = decide(store, chunk, entry)
    return decided.conflicts if isinstance(decided, Outcome) else ()


def write_commit(
    store: ReplicaStore, chunk: ChunkId, record: CommitRecord, revisions: Sequence[Revision]
) -> None:
    """Write a commit's revisions of `chunk`; the store extends the chunk's hash
    chain with it in the same transaction (`Store.apply_commit`)."""
    store.apply_commit(record, revisions)


def chunk_clock(store: ReplicaStore, chunk: ChunkId) -> int:
    """The newest commit time in the chunk's replica: its recorded clock, or a later
    commit applied earlier in the same transaction (`RaftGroups` records the clock
    once per batch of entries, after them all)."""
    clock = store.raft_time(chunk)
    written = store.changed_since(clock, chunk=chunk)
    return max((r.update_time for r in written), default=clock)


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
