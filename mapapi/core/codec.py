"""The only module that sees generated protobuf code (`mapapi/_pb`).

It converts between the core's dataclasses and the messages of
`proto/mapapi/v1/*.proto`, for storage (persisted views) and the wire.
"""

from __future__ import annotations

from google.protobuf.message import DecodeError

from mapapi._pb.mapapi.v1 import core_pb2, maps_pb2, types_pb2
from mapapi.core.errors import CorruptRepoError
from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId
from mapapi.core.transaction import Change, Conflict, Op
from mapapi.core.view import View

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


def encode_view(view: View) -> bytes:
    """Serialize a CLI view (a transaction kept between commands)."""
    state = core_pb2.ViewState(name=view.name, begin_time=view.begin_time, isolation=view.isolation)
    state.changes.extend(change_to_pb(c) for c in view.changes)
    for c in view.conflicts:
        entry = state.conflicts.add(table=c.table, item_id=c.item_id.to_bytes())
        entry.theirs.CopyFrom(revision_to_pb(c.theirs))
        if c.base is not None:
            entry.base.CopyFrom(revision_to_pb(c.base))
        if c.ours is not None:
            entry.ours.CopyFrom(change_to_pb(c.ours))
    state.read_set.extend(i.to_bytes() for i in sorted(view.read_set))
    for table, chunk in sorted(view.scopes, key=lambda s: (s[0], s[1] or "")):
        state.scopes.add(table=table, chunk=chunk.to_bytes() if chunk else b"")
    return bytes(state.SerializeToString())


def decode_view(blob: bytes) -> View:
    """A view from its serialized form.

    Raises:
        CorruptRepoError: the stored view does not parse.
    """
    state = core_pb2.ViewState()
    try:
        state.ParseFromString(blob)
        conflicts = [
            Conflict(
                c.table,
                ItemId.from_bytes(c.item_id),
                ChunkId.from_bytes(c.theirs.chunk_id),
                revision_from_pb(c.base) if c.HasField("base") else None,
                change_from_pb(c.ours) if c.HasField("ours") else None,
                revision_from_pb(c.theirs),
            )
            for c in state.conflicts
        ]
        return View(
            state.name,
            state.begin_time,
            "serializable" if state.isolation == "serializable" else "snapshot",
            [change_from_pb(c) for c in state.changes],
            conflicts,
            {ItemId.from_bytes(i) for i in state.read_set},
            {(s.table, ChunkId.from_bytes(s.chunk) if s.chunk else None) for s in state.scopes},
        )
    except (DecodeError, ValueError) as exc:
        raise CorruptRepoError(f"a stored view does not parse: {exc}") from exc
