"""The writer's side of a commit: lock, validate on the current replica, apply.

On one peer the "lock" is the store's exclusive section, which also keeps other
processes on the same repository out; validation and apply happen inside it,
so a commit is all-or-nothing and never interleaves with another (DESIGN §5).
"""

from __future__ import annotations

from collections.abc import Callable

from mapapi.clock import LamportClock
from mapapi.errors import ConflictError
from mapapi.history import CommitRecord, Revision
from mapapi.ids import CommitId, ItemId
from mapapi.store.base import Store
from mapapi.transaction import MergeFn, Transaction, build_revisions, validate


def commit_locally(
    store: Store,
    tx: Transaction,
    message: str,
    clock: LamportClock,
    try_merge: MergeFn | None,
    on_applied: Callable[[CommitRecord, list[Revision]], None] | None = None,
) -> CommitRecord | None:
    """Commit `tx` against `store` atomically.

    Returns:
        The commit record, or None when nothing was written.

    Raises:
        ConflictError: with (base, ours, theirs) for every conflicting item.
    """
    with store.exclusive():
        changes = tx.changes
        read_ids: set[ItemId] = set()
        if tx.isolation == "serializable":
            read_ids = tx.read_set
            for table, chunk in tx.scopes:
                # Phantoms: anything written in a scanned range after we began.
                read_ids |= {
                    r.item_id for r in store.changed_since(tx.begin_time, table=table, chunk=chunk)
                }
        latest = store.latest([c.item_id for c in changes] + sorted(read_ids))
        accepted, conflicts = validate(
            changes,
            latest,
            tx.since,
            read_set=read_ids,
            try_merge=try_merge,
            base_of=lambda item_id: store.read(item_id, tx.begin_time),
        )
        clock.advance_to(store.clock())
        if conflicts:
            raise ConflictError(conflicts, tx, resolved_at=store.clock())
        if not accepted:
            return None
        time = clock.tick()
        record = CommitRecord(
            CommitId.new(),
            time,
            tx.author,
            message,
            tuple(sorted({c.chunk_id for c in accepted})),
        )
        revisions = build_revisions(accepted, latest, time, tx.author, record.id)
        store.apply_commit(record, revisions)
    tx.committed(revisions)
    if on_applied is not None:
        on_applied(record, revisions)
    return record
