"""What a chunk's leader checks of a writer's proposal before it appends it
(DESIGN §11, §13), and the application's commit rules (`CommitRule`).

Every holder decides a proposal from its replica and the proposal alone
(`swarm/apply.py`), so a proposal that would break the store must never enter
the log, whoever sends it: the leader refuses, before appending, a proposal or
a readers' floor from a peer that is no member of the chunk's group, a proposal
under the id of a commit that exists (its revisions would join that commit's) or
that speaks for another peer, writes to another chunk or table than the chunk's,
to an item of another chunk, twice to one item, or carries a payload that is not
of the table's type (or any, for a removal) or is over the size limit, and a
commit decision for a transaction prepared here by another peer (only its
coordinator decides commit; anyone may decide abort, as recovery does), and
an entry whose time is more than `limits.MAX_CLOCK_JUMP` ahead of the leader's
clock: applying it moves the chunk's clock there, and one entry at
`limits.MAX_LAMPORT` would stamp every later commit of the chunk with a time no
peer accepts (found by the wire fuzzer).
"""

from __future__ import annotations

from collections.abc import Collection, Sequence
from typing import Protocol

from mapapi.core import codec, limits
from mapapi.core.change import Change, Op
from mapapi.core.errors import NotParticipatingError, UsageError
from mapapi.core.ids import ChunkId, PeerId
from mapapi.core.proposal import LogEntry, Proposal, TxDecision
from mapapi.core.table import TableDescriptor
from mapapi.store.base import ReplicaStore, Store


def checked_entry(
    store: ReplicaStore,
    chunk: ChunkId,
    data: bytes,
    sender: PeerId,
    members: Collection[PeerId],
    now: int,
) -> LogEntry:
    """A writer's entry to `chunk`'s log, parsed and checked (`check_proposal`)
    before its leader proposes it; any thread (a big one is parsed in a worker).

    Raises:
        CorruptRepoError: the entry does not parse (it would not apply).
        NotParticipatingError, UsageError, LimitExceeded: see `check_proposal`.
    """
    entry = codec.decode_entry(data)
    check_proposal(store, chunk, entry, sender, members, now)
    return entry


def check_proposal(
    store: ReplicaStore,
    chunk: ChunkId,
    entry: LogEntry,
    sender: PeerId,
    members: Collection[PeerId],
    now: int,
) -> None:
    """Refuse an entry from `sender` to `chunk`'s log that would break the store
    (see the module docstring); `members` are the group's, `now` the leader's clock.

    Raises:
        ChunkNotFound: this peer does not hold `chunk`.
        NotParticipatingError: `sender` is no member of the chunk's group.
        UsageError: naming the first problem found.
        LimitExceeded: a payload over `MAX_PAYLOAD_BYTES`, a time too far ahead.
    """
    limits.clock_jump(now, entry.time)
    if isinstance(entry, TxDecision):
        _check_decision(store, chunk, entry, sender)
        return
    if sender not in members:
        raise NotParticipatingError(
            f"peer {sender.short} is no member of chunk {chunk.short}'s group; "
            "`mapctl chunk participate` there first"
        )
    if not isinstance(entry, Proposal):
        return
    limits.clock_jump(now, entry.begin_time)
    if store.commit_record(entry.commit_id) and store.raft_tx(chunk, entry.commit_id) is None:
        raise UsageError(
            f"commit {entry.commit_id.short} exists already: a proposal needs a new commit id"
        )
    if entry.author != sender:
        raise UsageError(
            f"a proposal by {entry.author.short} was sent by {sender.short}: a peer "
            "proposes its own commits only"
        )
    table = store.chunk_table(chunk)
    descriptor = _descriptor(store, table)
    latest = store.latest([c.item_id for c in entry.changes])
    seen = set()
    for change in entry.changes:
        what = f"item {change.item_id.short} of commit {entry.commit_id.short}"
        if change.item_id in seen:
            raise UsageError(f"{what} is changed twice in one proposal")
        seen.add(change.item_id)
        if (change.chunk_id, change.table) != (chunk, table):
            raise UsageError(f"{what} is not filed under chunk {chunk.short} and table {table!r}")
        previous = latest.get(change.item_id)
        if previous is not None and previous.chunk_id != chunk:
            raise UsageError(f"{what} belongs to chunk {previous.chunk_id.short}")
        _check_payload(what, change, descriptor)


def _check_decision(store: ReplicaStore, chunk: ChunkId, entry: TxDecision, sender: PeerId) -> None:
    if not entry.commit:
        return
    kept = store.raft_tx(chunk, entry.commit_id)
    if kept is None or not kept.data:
        return
    prepared = codec.decode_entry(kept.data)
    if isinstance(prepared, Proposal) and prepared.author != sender:
        raise UsageError(
            f"peer {sender.short} decided commit {entry.commit_id.short}, which "
            f"{prepared.author.short} coordinates: only a coordinator decides commit"
        )


def _check_payload(what: str, change: Change, descriptor: TableDescriptor | None) -> None:
    if change.op is Op.REMOVE:
        if change.data:
            raise UsageError(f"{what} removes the item but carries a payload")
        return
    limits.payload(len(change.data))
    if descriptor is not None:
        descriptor.decode(change.data)  # UsageError if it is not of the table's type


def _descriptor(store: ReplicaStore, table: str) -> TableDescriptor | None:
    """The table's descriptor; None when its type is unknown in this process
    (its payloads cannot be checked, or read, here)."""
    try:
        return TableDescriptor.named(table, store.tables()[table])
    except UsageError:
        return None


class CommitRule(Protocol):
    """An invariant an application layer keeps over its tables, given to `Peer`
    at construction and checked by the writer on every commit, over the whole
    transaction, on its replicas (alone: in the store's exclusive section,
    `swarm/commit.py`; in a swarm: before proposing, `swarm/log_commit.py`), so
    it holds whoever commits: a CLI, a script or an import.
    """

    def check(self, store: Store, changes: Sequence[Change]) -> None:
        """Refuse `changes` (the accepted write set) by raising a `UsageError`;
        cost should follow the size of `changes`, not of the tables."""
