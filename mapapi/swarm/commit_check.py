"""What a holder checks of a commit batch before it stages it (DESIGN §5, §11).

The writer holds the chunk's lock, so its batch is the commit; but a batch that
breaks the store's invariants must never be applied, whoever sends it: every
revision must belong to the locked chunk and its table, be stamped with the
commit's id, time and author, come after the item's newest revision here (the
lock grant merged clocks, so a real commit's time always does), keep the
item's insert time, and carry a payload of the table's type (or none, for a
removal). An item of another chunk may not be written through this one.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

from mapapi.core import limits
from mapapi.core.errors import UsageError
from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, PeerId
from mapapi.core.table import TableDescriptor
from mapapi.core.transaction import Change
from mapapi.store.base import ReplicaStore, Store


def check_batch(
    store: ReplicaStore,
    chunk: ChunkId,
    record: CommitRecord,
    revisions: Sequence[Revision],
    writer: PeerId,
) -> None:
    """Refuse a batch that would break the store (see the module docstring).

    Raises:
        ChunkNotFound: this peer does not hold `chunk`.
        UsageError: naming the first problem found.
    """
    table = store.chunk_table(chunk)
    short = chunk.short
    if record.author != writer:
        raise UsageError(
            f"commit {record.id.short} is by {record.author.short}, sent by {writer.short}"
        )
    if (chunk in record.chunks) != bool(revisions):
        # An empty batch only locks a chunk a serializable commit read.
        raise UsageError(
            f"commit {record.id.short} {'does not list' if revisions else 'lists'} chunk "
            f"{short} but its batch {'writes to it' if revisions else 'writes nothing'}"
        )
    descriptor = _descriptor(store, table)
    latest = store.latest([r.item_id for r in revisions])
    seen = set()
    for r in revisions:
        what = f"item {r.item_id.short} of commit {record.id.short}"
        if r.item_id in seen:
            raise UsageError(f"{what} appears twice in one batch")
        seen.add(r.item_id)
        if (r.chunk_id, r.table, r.commit_id, r.author) != (chunk, table, record.id, writer):
            raise UsageError(
                f"{what} is not filed under chunk {short}, table {table!r} and the commit"
            )
        if r.update_time != record.time:
            raise UsageError(f"{what} is stamped {r.update_time}, its commit {record.time}")
        _check_history(what, r, latest.get(r.item_id), chunk)
        _check_payload(what, r, descriptor)


def _check_history(what: str, r: Revision, previous: Revision | None, chunk: ChunkId) -> None:
    if previous is None:
        if r.insert_time != r.update_time:
            raise UsageError(f"{what} is new here, but claims it was inserted at {r.insert_time}")
        return
    if previous.chunk_id != chunk:
        raise UsageError(f"{what} belongs to chunk {previous.chunk_id.short}")
    if previous.commit_id == r.commit_id:
        return  # the same commit again: applying it twice changes nothing
    if previous.update_time >= r.update_time:
        raise UsageError(
            f"{what} is stamped {r.update_time}, not after its newest revision "
            f"({previous.update_time})"
        )
    if r.insert_time not in (r.update_time, previous.insert_time):
        raise UsageError(f"{what} changes the item's insert time")


def _check_payload(what: str, r: Revision, descriptor: TableDescriptor | None) -> None:
    if r.removed:
        if r.data:
            raise UsageError(f"{what} removes the item but carries a payload")
        return
    limits.payload(len(r.data))
    if descriptor is not None:
        descriptor.decode(r.data)  # UsageError if it is not of the table's type


def _descriptor(store: ReplicaStore, table: str) -> TableDescriptor | None:
    """The table's descriptor; None when its type is unknown in this process
    (its payloads cannot be checked, or read, here)."""
    try:
        return TableDescriptor.named(table, store.tables()[table])
    except UsageError:
        return None


class CommitRule(Protocol):
    """An invariant an application layer keeps over its tables, given to `Peer`
    at construction and checked by the writer on every commit, on the current
    replica while it holds the chunks' locks (DESIGN §5 step 4), so it holds
    whoever commits: a CLI, a script or an import.
    """

    def check(self, store: Store, changes: Sequence[Change]) -> None:
        """Refuse `changes` (the accepted write set) by raising a `UsageError`;
        cost should follow the size of `changes`, not of the tables."""
