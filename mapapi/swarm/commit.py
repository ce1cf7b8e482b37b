"""A lone peer's commit: validate on the replica and apply, in the store's
exclusive section, which also keeps other processes on the same repository out
(`commit_locally`). In a swarm every commit goes through the chunks' Raft logs
instead (`swarm/log_commit.py`), decided by every holder with the same pure
validation (`swarm/apply.py`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from mapapi.core.change import Change, Conflict, MergeFn
from mapapi.core.clock import LamportClock
from mapapi.core.errors import (
    ConflictError,
    PeerNotRunning,
)
from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import CommitId, ItemId, PeerId
from mapapi.core.transaction import Transaction
from mapapi.core.validate import build_revisions, validate
from mapapi.store.base import ReplicaStore, Store
from mapapi.swarm import apply

if TYPE_CHECKING:  # the network stack loads only for a peer on the network
    from collections.abc import Sequence

    from mapapi.swarm.commit_check import CommitRule


@dataclass
class Decision:
    """What validation decided: the revisions to write under a new commit, or nothing."""

    record: CommitRecord | None
    revisions: list[Revision]


def _decide(
    store: Store,
    tx: Transaction,
    message: str,
    clock: LamportClock,
    try_merge: MergeFn | None,
    rules: Sequence[CommitRule] = (),
) -> Decision:
    """Validate `tx` on the current replica and stamp its revisions (no writes).

    Raises:
        ConflictError: with (base, ours, theirs) for every conflicting item.
        UsageError: a rule refuses the accepted changes.
    """
    try:
        accepted, latest = _checked(store, tx, try_merge, rules)
    finally:
        clock.advance_to(store.clock())
    if not accepted:
        return Decision(None, [])
    return _stamped(tx, message, accepted, latest, clock.tick())


def _checked(
    store: Store, tx: Transaction, try_merge: MergeFn | None, rules: Sequence[CommitRule]
) -> tuple[list[Change], dict[ItemId, Revision]]:
    """The changes of `tx` that validation accepts (all, or ConflictError), once
    `rules` accept them, with the newest revisions of their items (any thread)."""
    accepted, latest, conflicts = _validate(store, tx, try_merge)
    if conflicts:
        raise ConflictError(conflicts, tx, seen_at=store.clock())
    for rule in rules:
        rule.check(store, accepted)
    return accepted, latest


def _stamped(
    tx: Transaction,
    message: str,
    accepted: list[Change],
    latest: dict[ItemId, Revision],
    time: int,
) -> Decision:
    """The commit of the `accepted` changes at `time`: its record and revisions."""
    chunks = tuple(sorted({c.chunk_id for c in accepted}))
    record = CommitRecord(CommitId.new(), time, tx.author, message, chunks, tx.author_name, tx.view)
    return Decision(record, build_revisions(accepted, latest, time, tx.author, record.id))


def _validate(
    store: Store, tx: Transaction, try_merge: MergeFn | None
) -> tuple[list[Change], dict[ItemId, Revision], list[Conflict]]:
    """Run the pure validation on this replica: (accepted changes, newest revisions, conflicts)."""
    changes = tx.changes
    read_ids = apply.read_ids(store, tx.isolation, tx.read_set, tx.scopes, tx.begin_time)
    latest = store.latest([c.item_id for c in changes] + sorted(read_ids))
    accepted, conflicts = validate(
        changes,
        latest,
        tx.since,
        read_set=read_ids,
        try_merge=try_merge,
        base_of=lambda item_id: store.read(item_id, tx.begin_time),
    )
    return accepted, latest, conflicts


def commit_locally(
    store: Store,
    tx: Transaction,
    message: str,
    clock: LamportClock,
    try_merge: MergeFn | None,
    rules: Sequence[CommitRule] = (),
) -> Decision:
    """Commit `tx` against `store` atomically (no swarm), if `rules` accept it.

    Returns:
        The commit record (None when nothing was written) with the revisions
        written, so the caller need not read them back from the store.

    Raises:
        ConflictError: with (base, ours, theirs) for every conflicting item.
    """
    with store.exclusive():
        decision = _decide(store, tx, message, clock, try_merge, rules)
        if decision.record is not None:
            store.apply_commit(decision.record, decision.revisions)
    tx.committed(decision.revisions)
    return decision


def refuse_shared(store: ReplicaStore, me: PeerId, tx: Transaction) -> None:
    """Alone, a commit may not touch a chunk other peers hold: they would never
    see it (DESIGN §5: every commit reaches every holder).

    Raises:
        PeerNotRunning: `tx` changes a chunk that `me` shares with other peers.
    """
    for chunk in sorted({c.chunk_id for c in tx.changes}):
        if any(p != me for p in store.holders(chunk)):
            raise PeerNotRunning(
                f"chunk {chunk.short} is shared with other peers; commit through the "
                "running peer (`mapctl peer start --join ADDR`)"
            )
