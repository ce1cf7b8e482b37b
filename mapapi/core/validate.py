"""Deciding a commit on a replica (DESIGN §5 step 4), pure: which changes hold
against the newest revisions, which conflict, and the revisions the accepted
ones become. A lone peer's commit, the lock path and every holder of a chunk's
Raft log (`swarm/apply.py`) decide with these same functions.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import replace

from mapapi.core.change import Change, Conflict, MergeFn, Op
from mapapi.core.history import Revision
from mapapi.core.ids import CommitId, ItemId, PeerId


def validate(
    changes: Iterable[Change],
    latest: Mapping[ItemId, Revision],
    since: Callable[[ItemId], int],
    *,
    read_set: Iterable[ItemId] = (),
    try_merge: MergeFn | None = None,
    base_of: Callable[[ItemId], Revision | None] = lambda _: None,
) -> tuple[list[Change], list[Conflict]]:
    """Decide a commit on the current replica (pure).

    Args:
        changes: the write set.
        latest: the newest revision of every item in the write and read sets.
        since: per item, the time after which a foreign write is a conflict
            (the begin time, or this transaction's own last commit of the item).
        read_set: items read but not written (serializable isolation only).
        try_merge: the table's auto-merge hook for update/update conflicts.
        base_of: the item at the begin time, for conflict reports.

    Returns:
        The changes to write (merged where a policy merged them) and the conflicts.
    """
    accepted: list[Change] = []
    conflicts: list[Conflict] = []
    written: set[ItemId] = set()
    for change in changes:
        written.add(change.item_id)
        theirs = latest.get(change.item_id)
        if change.op is Op.INSERT:
            # A tombstone we already saw (before our begin, or our own removal)
            # does not make the id "exist": re-inserting it is no conflict.
            if theirs is None or (theirs.removed and theirs.update_time <= since(change.item_id)):
                accepted.append(change)
            else:
                conflicts.append(_conflict(change.item_id, change, theirs, base_of))
            continue
        if theirs is None or theirs.update_time <= since(change.item_id):
            accepted.append(change)
            continue
        if change.op is Op.UPDATE and not theirs.removed and try_merge is not None:
            merged = try_merge(change, theirs, base_of(change.item_id))
            if merged is not None:
                accepted.append(replace(change, data=merged))
                continue
        conflicts.append(_conflict(change.item_id, change, theirs, base_of))
    for item_id in read_set:
        theirs = latest.get(item_id)
        if item_id in written or theirs is None:
            continue
        if theirs.update_time > since(item_id):
            conflicts.append(_conflict(item_id, None, theirs, base_of))
    return accepted, conflicts


def _conflict(
    item_id: ItemId,
    ours: Change | None,
    theirs: Revision,
    base_of: Callable[[ItemId], Revision | None],
) -> Conflict:
    base = base_of(item_id)
    if base is not None and base.removed:
        base = None
    return Conflict(theirs.table, item_id, theirs.chunk_id, base, ours, theirs)


def build_revisions(
    changes: Iterable[Change],
    latest: Mapping[ItemId, Revision],
    time: int,
    author: PeerId,
    commit_id: CommitId,
) -> list[Revision]:
    """Stamp accepted changes as revisions of one commit (pure)."""
    out = []
    for change in changes:
        previous = latest.get(change.item_id)
        inserted = time if change.op is Op.INSERT or previous is None else previous.insert_time
        out.append(
            Revision(
                change.item_id,
                change.table,
                change.chunk_id,
                b"" if change.op is Op.REMOVE else change.data,
                inserted,
                time,
                change.op is Op.REMOVE,
                author,
                commit_id,
            )
        )
    return out
