"""The storage codec: the core's dataclasses as messages of `proto/mapapi/v1/core.proto`.

It converts revisions, commit records, changes, conflicts and persisted views,
for storage and for the wire codec (`mapapi.net.codec`, which sees only the
envelope of `wire.proto`). It is not the only module that sees generated
protobuf: the Chord index's values are `lookup.proto` messages that
`mapapi.lookup.spatial_index` (entries, filters) and `mapapi.swarm.subscriptions`
(subscriptions) read and write, and the application layer reads `maps.proto` types.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from typing import Any

from google.protobuf.message import DecodeError

from mapapi._pb.mapapi.v1 import core_pb2, maps_pb2, types_pb2
from mapapi.core import limits, pb_parts
from mapapi.core.change import Change, Conflict, Op
from mapapi.core.chunk_state import ChunkState, TxState
from mapapi.core.errors import CorruptRepoError
from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId
from mapapi.core.proposal import LogEntry, Proposal, TimeFloor, TxDecision
from mapapi.core.transaction import Isolation
from mapapi.core.view import Scope, View

_GENERATED = (core_pb2, maps_pb2, types_pb2)  # registers every mapapi.v1 type


def ensure_registered() -> None:
    """Make sure the mapapi.v1 message types are in the default descriptor pool.

    Importing this module does it; the function exists so callers can say why
    they import it.
    """


def revision_to_pb(r: Revision) -> core_pb2.Revision:
    """A revision as its protobuf message."""
    return core_pb2.Revision(
        item_id=r.item_id.to_bytes(),
        table=r.table,
        chunk_id=r.chunk_id.to_bytes(),
        data=r.data,
        insert_time=r.insert_time,
        update_time=r.update_time,
        removed=r.removed,
        author=r.author.to_bytes(),
        commit_id=r.commit_id.to_bytes(),
    )


def revision_from_pb(m: core_pb2.Revision) -> Revision:
    """A revision from its protobuf message (raises ValueError on bad ids)."""
    return Revision(
        ItemId.from_bytes(m.item_id),
        m.table,
        ChunkId.from_bytes(m.chunk_id),
        m.data,
        m.insert_time,
        m.update_time,
        m.removed,
        PeerId.from_bytes(m.author),
        CommitId.from_bytes(m.commit_id),
    )


def commit_record_to_pb(r: CommitRecord) -> core_pb2.CommitRecord:
    """A commit record as its protobuf message."""
    return core_pb2.CommitRecord(
        id=r.id.to_bytes(),
        time=r.time,
        author=r.author.to_bytes(),
        message=r.message,
        chunks=[c.to_bytes() for c in r.chunks],
        author_name=r.author_name,
        view=r.view,
    )


def commit_record_from_pb(m: core_pb2.CommitRecord) -> CommitRecord:
    """A commit record from its protobuf message (raises ValueError on bad ids)."""
    return CommitRecord(
        CommitId.from_bytes(m.id),
        m.time,
        PeerId.from_bytes(m.author),
        m.message,
        tuple(ChunkId.from_bytes(c) for c in m.chunks),
        m.author_name,
        m.view,
    )


def change_to_pb(c: Change) -> core_pb2.Change:
    """A buffered change as its protobuf message."""
    return core_pb2.Change(
        op=c.op.name,  # the proto enum uses the same names
        table=c.table,
        item_id=c.item_id.to_bytes(),
        chunk_id=c.chunk_id.to_bytes(),
        data=c.data,
    )


def change_from_pb(m: core_pb2.Change) -> Change:
    """A buffered change from its protobuf message."""
    return Change(
        Op(m.op),
        m.table,
        ItemId.from_bytes(m.item_id),
        ChunkId.from_bytes(m.chunk_id),
        m.data,
    )


def conflict_to_pb(c: Conflict) -> core_pb2.Conflict:
    """A conflict as its protobuf message (its chunk is its newest revision's)."""
    entry = core_pb2.Conflict(table=c.table, item_id=c.item_id.to_bytes())
    entry.theirs.CopyFrom(revision_to_pb(c.theirs))
    if c.base is not None:
        entry.base.CopyFrom(revision_to_pb(c.base))
    if c.ours is not None:
        entry.ours.CopyFrom(change_to_pb(c.ours))
    return entry


def conflict_from_pb(m: core_pb2.Conflict) -> Conflict:
    """A conflict from its protobuf message (raises ValueError on bad ids)."""
    return Conflict(
        m.table,
        ItemId.from_bytes(m.item_id),
        ChunkId.from_bytes(m.theirs.chunk_id),
        revision_from_pb(m.base) if m.HasField("base") else None,
        change_from_pb(m.ours) if m.HasField("ours") else None,
        revision_from_pb(m.theirs),
    )


def encode_view(view: View) -> bytes:
    """Serialize a CLI view (a transaction kept between commands)."""
    state = core_pb2.ViewState(
        name=view.name, begin_time=view.begin_time, isolation=view.isolation, stale=view.stale
    )
    state.changes.extend(change_to_pb(c) for c in view.changes)
    state.conflicts.extend(conflict_to_pb(c) for c in view.conflicts)
    _put_reads(state, view.read_set, view.scopes)
    return bytes(state.SerializeToString())


def decode_view(blob: bytes) -> View:
    """A view from its serialized form.

    Raises:
        CorruptRepoError: the stored view does not parse.
    """
    state = core_pb2.ViewState()
    try:
        state.ParseFromString(blob)
        conflicts = [conflict_from_pb(c) for c in state.conflicts]
        return View(
            state.name,
            state.begin_time,
            _isolation(state.isolation),
            [change_from_pb(c) for c in state.changes],
            conflicts,
            set(_read_set(state)),
            set(_scopes(state)),
            state.stale,
        )
    except (DecodeError, ValueError) as exc:
        raise CorruptRepoError(f"a stored view does not parse: {exc}") from exc


def encode_entry(entry: LogEntry) -> bytes:
    """Serialize what a chunk's Raft log entry carries: a proposal (a prepare when
    it names participants), a transaction's decision or a readers' floor."""
    if isinstance(entry, TxDecision):
        decision = core_pb2.TxDecision(
            commit_id=entry.commit_id.to_bytes(), commit=entry.commit, time=entry.time
        )
        return bytes(core_pb2.ChunkLogEntry(decision=decision).SerializeToString())
    if isinstance(entry, TimeFloor):
        floor = core_pb2.TimeFloor(time=entry.time)
        return bytes(core_pb2.ChunkLogEntry(floor=floor).SerializeToString())
    m = core_pb2.CommitProposal(
        commit_id=entry.commit_id.to_bytes(),
        time=entry.time,
        author=entry.author.to_bytes(),
        author_name=entry.author_name,
        view=entry.view,
        message=entry.message,
        begin_time=entry.begin_time,
        isolation=entry.isolation,
    )
    m.changes.extend(change_to_pb(c) for c in entry.changes)
    for item_id, time in sorted(entry.since.items()):
        m.since.add(item_id=item_id.to_bytes(), time=time)
    _put_reads(m, entry.read_set, entry.scopes)
    m.participants.extend(c.to_bytes() for c in entry.participants)
    return bytes(core_pb2.ChunkLogEntry(proposal=m).SerializeToString())


def decode_entry(data: bytes) -> LogEntry:
    """What a chunk's log entry carries (`encode_entry`).

    Raises:
        CorruptRepoError: the entry does not parse (a damaged log), or carries a
            time above `limits.MAX_LAMPORT` (no store could keep it).
    """
    entry = core_pb2.ChunkLogEntry()
    try:
        entry.ParseFromString(data)
        if entry.WhichOneof("body") == "decision":
            d = entry.decision
            return TxDecision(CommitId.from_bytes(d.commit_id), d.commit, _time(d.time))
        if entry.WhichOneof("body") == "floor":
            return TimeFloor(_time(entry.floor.time))
        if entry.WhichOneof("body") != "proposal":
            raise ValueError("the entry carries no proposal, decision or floor")
        m = entry.proposal
        return Proposal(
            CommitId.from_bytes(m.commit_id),
            _time(m.time),
            PeerId.from_bytes(m.author),
            m.author_name,
            m.view,
            m.message,
            _time(m.begin_time),
            _isolation(m.isolation),
            tuple(change_from_pb(c) for c in m.changes),
            {ItemId.from_bytes(s.item_id): _time(s.time) for s in m.since},
            frozenset(_read_set(m)),
            frozenset(_scopes(m)),
            tuple(ChunkId.from_bytes(c) for c in m.participants),
        )
    except (DecodeError, ValueError) as exc:
        raise CorruptRepoError(f"an entry in a chunk's log does not parse: {exc}") from exc


def _time(value: int) -> int:
    """A logical time from a log entry (`LimitExceeded`, a ValueError, above the cap)."""
    return limits.lamport("a time in a chunk's log entry", value)


PART_ITEMS = 2000
"""Rows of a chunk's state serialized in one call (about 300 KB)."""


def encode_chunk_state(
    state: ChunkState, revisions: Sequence[core_pb2.Revision] | None = None
) -> bytes:
    """Serialize a chunk's whole state (a Raft snapshot's data), in parts of
    `PART_ITEMS` rows whose bytes are joined (`core/pb_parts.py`: no call holds
    the interpreter lock for the whole chunk). `revisions`, when given, are the
    state's revisions already as messages (`state.revisions` is then not read)."""
    head = core_pb2.ChunkSnapshot(
        table=state.table, type_name=state.type_name, time=state.time, replication=state.replication
    )
    out = [head.SerializeToString()]
    if revisions is None:
        revisions = [revision_to_pb(r) for r in state.revisions]
    for i in range(0, len(revisions), PART_ITEMS):
        m = core_pb2.ChunkSnapshot()
        m.revisions.extend(revisions[i : i + PART_ITEMS])
        out.append(m.SerializeToString())
    for i in range(0, len(state.commits), PART_ITEMS):
        m = core_pb2.ChunkSnapshot()
        m.commits.extend(commit_record_to_pb(c) for c in state.commits[i : i + PART_ITEMS])
        out.append(m.SerializeToString())
    m = core_pb2.ChunkSnapshot()
    for tx in state.txs:
        m.txs.add(commit_id=tx.commit_id.to_bytes(), state=tx.state, time=tx.time, data=tx.data)
    for commit, link in state.compacted:
        m.compacted.add(commit_id=commit.to_bytes(), link=link)
    out.append(m.SerializeToString())
    return b"".join(out)


def decode_chunk_state(data: bytes) -> ChunkState:
    """The state `encode_chunk_state` wrote.

    Raises:
        CorruptRepoError: it does not parse (a damaged snapshot).
    """
    m = core_pb2.ChunkSnapshot()
    try:
        for part in pb_parts.parts(data):  # merged part by part, as it was written
            m.MergeFromString(part)
        return ChunkState(
            m.table,
            m.type_name,
            m.time,
            tuple(revision_from_pb(r) for r in m.revisions),
            tuple(commit_record_from_pb(c) for c in m.commits),
            tuple(
                TxState(CommitId.from_bytes(t.commit_id), t.state, t.time, t.data) for t in m.txs
            ),
            m.replication,
            tuple((CommitId.from_bytes(c.commit_id), c.link) for c in m.compacted),
        )
    except (DecodeError, ValueError) as exc:
        raise CorruptRepoError(f"a chunk's snapshot does not parse: {exc}") from exc


# The read set and scanned scopes, stored alike in a view and in a proposal.
def _put_reads(m: Any, read_set: Iterable[ItemId], scopes: Iterable[Scope]) -> None:
    m.read_set.extend(i.to_bytes() for i in sorted(read_set))
    for table, chunk in sorted(scopes, key=lambda s: (s[0], s[1] or "")):
        m.scopes.add(table=table, chunk=chunk.to_bytes() if chunk else b"")


def _read_set(m: Any) -> Iterator[ItemId]:
    return (ItemId.from_bytes(i) for i in m.read_set)


def _scopes(m: Any) -> Iterator[Scope]:
    return ((s.table, ChunkId.from_bytes(s.chunk) if s.chunk else None) for s in m.scopes)


def _isolation(text: str) -> Isolation:
    return "serializable" if text == "serializable" else "snapshot"
