"""The writer's side of a commit: lock, validate on the current replica, apply.

On a peer with no swarm the "lock" is the store's exclusive section, which also
keeps other processes on the same repository out (`commit_locally`). In a swarm
(`commit_distributed`) the writer write-locks every touched chunk at every
holder, in ascending `ChunkId` order (no deadlock), validates on its own
replica (current once every holder granted), stages one batch per chunk at
every other holder, applies locally, and sends apply+unlock (DESIGN §5).
Validation is the same pure function either way.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from mapapi.core.clock import LamportClock
from mapapi.core.errors import (
    CommitUncertain,
    ConflictError,
    LockNotHeld,
    LockTimeout,
    PeerNotRunning,
)
from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId
from mapapi.core.transaction import Change, Conflict, MergeFn, Transaction
from mapapi.core.validate import build_revisions, validate
from mapapi.store.base import ReplicaStore, Store
from mapapi.store.offload import off_loop
from mapapi.swarm import apply
from mapapi.swarm.quorum import is_quorum

if TYPE_CHECKING:  # the network stack loads only for a peer on the network
    from collections.abc import Awaitable, Callable, Sequence

    from mapapi.swarm.commit_check import CommitRule
    from mapapi.swarm.lock_client import Held, LockService
    from mapapi.swarm.replication import Replicator


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


async def _decide_off_loop(
    store: Store,
    tx: Transaction,
    message: str,
    clock: LamportClock,
    try_merge: MergeFn | None,
    rules: Sequence[CommitRule] = (),
) -> Decision:
    """`_decide`, with the validation and the stamping in a worker thread (a
    mission of 100,000 rows takes seconds of both: issue 14 §1); the clock, which
    every message on the loop ticks, is ticked here on the loop."""
    try:
        accepted, latest = await off_loop(store, _checked, store, tx, try_merge, rules)
    finally:
        clock.advance_to(store.clock())
    if not accepted:
        return Decision(None, [])
    time = clock.tick()
    return await off_loop(store, _stamped, tx, message, accepted, latest, time)


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


def _precheck(store: Store, tx: Transaction, try_merge: MergeFn | None) -> None:
    """Raise ConflictError now if the local replica already shows `tx` in conflict.

    Called once the arbiter granted, before the other holders are asked: a
    conflict seen here is final (history only grows), so a doomed commit costs
    one lock at the arbiter instead of one at every holder. Passing proves
    nothing, since this replica may lag until every holder granted; `_decide`
    validates for real then.
    """
    _, _, conflicts = _validate(store, tx, try_merge)
    if conflicts:
        raise ConflictError(conflicts, tx, seen_at=store.clock())


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


def _check_confirmed(
    held: Sequence[Held],
    record: CommitRecord,
    unconfirmed: Sequence[tuple[ChunkId, PeerId]],
    me: PeerId,
) -> None:
    """Raise CommitUncertain unless, for every chunk, the holders that applied the
    commit (this peer and those that confirmed) are a quorum of its holders:
    only then does every later quorum, and so every eviction, include one of
    them (`mapapi.swarm.quorum`)."""
    missing = {(c, p) for c, p in unconfirmed}
    for h in held:
        applied = [p for p in h.tokens if p == me or (h.chunk, p) not in missing]
        if not is_quorum(applied, h.tokens):
            raise CommitUncertain(
                f"commit {record.id.short} is applied here, but only {len(applied)} of the "
                f"{len(h.tokens)} holders of chunk {h.chunk.short} confirmed it; if this peer "
                "is cut off from the others, they decide whether it stays when they evict "
                "this peer"
            )


def _chunks_to_lock(store: ReplicaStore, tx: Transaction) -> list[ChunkId]:
    """Written chunks, plus the chunks a serializable transaction read, in id order."""
    chunks = {c.chunk_id for c in tx.changes}
    if tx.isolation == "serializable":
        chunks |= {c for _, c in tx.scopes if c is not None}
        chunks |= {cid for i in tx.read_set if (cid := store.item_chunk(i)) is not None}
        for table, chunk in tx.scopes:
            if chunk is None:
                chunks |= {c.id for c in store.chunks(table)}
    return sorted(chunks)


async def commit_distributed(
    store: ReplicaStore,
    locks: LockService,
    replicator: Replicator,
    tx: Transaction,
    message: str,
    clock: LamportClock,
    try_merge: MergeFn | None,
    after: Callable[[CommitRecord, list[Revision]], Awaitable[None]] | None = None,
    rules: Sequence[CommitRule] = (),
) -> CommitRecord | None:
    """Commit `tx` across every holder of the chunks it touches; `after` runs once
    the commit is applied everywhere, while this peer still holds its own locks
    (so the next commit to those chunks waits for it; it must not raise).

    Raises:
        ConflictError: as on one peer; every lock is released, nothing written.
        LockTimeout, NetworkError: a holder did not grant or stage in time, or
            a lease ran out before the commit was staged everywhere (the
            holders' fencing refused it); nothing was applied anywhere (retriable).
    """
    from mapapi.swarm.lock_client import Held

    held: list[Held] = []
    decision = Decision(None, [])
    pushed = False
    try:
        for chunk in _chunks_to_lock(store, tx):
            held.append(
                await replicator.lock(
                    chunk, lambda: off_loop(store, _precheck, store, tx, try_merge)
                )
            )
        decision = await _decide_off_loop(store, tx, message, clock, try_merge, rules)
        record = decision.record
        if record is not None:
            try:
                unconfirmed = await replicator.push(
                    held,
                    record,
                    decision.revisions,
                    lambda: off_loop(store, store.apply_commit, record, decision.revisions),
                )
            except LockNotHeld as exc:
                raise LockTimeout(
                    f"the write lease ran out before commit {record.id.short} was staged at "
                    f"every holder, so it was refused and nothing was written; retry ({exc})"
                ) from exc
            pushed = True
            if after is not None:
                await after(record, decision.revisions)
            _check_confirmed(held, record, unconfirmed, locks.me)
    finally:
        if decision.record is not None and not pushed:
            await replicator.abort(held, decision.record.id)
        for h in reversed(held):
            # After a push, the other holders released with the apply message.
            mine = (
                Held(h.chunk, {p: t for p, t in h.tokens.items() if p == locks.me}) if pushed else h
            )
            await locks.release(mine)
    tx.committed(decision.revisions)
    return decision.record
