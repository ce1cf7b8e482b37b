"""The Raft core's values in the shell's other languages (DESIGN §13): node ids
from peer ids, messages on the wire (`RaftMessage`), entries and state in the
store (`LogRow`, `RaftRecord`). Conversions only: no I/O, no decisions.
"""

from __future__ import annotations

from collections.abc import Iterable

from mapapi.core.ids import ChunkId, PeerId
from mapapi.net.messages import RaftEntry, RaftMessage
from mapapi.store.base import LogRow, RaftRecord
from mapapi.swarm.raft_types import (
    Config,
    Entry,
    EntryKind,
    HardState,
    Message,
    MessageKind,
    PersistentState,
    Snapshot,
)


def node_id(peer: PeerId) -> int:
    """The peer's node id in every group: the top 63 bits of its id (never 0, the
    core's "no node"; 63 bits so it fits SQLite's signed integers)."""
    return (int.from_bytes(peer.to_bytes(), "big") >> 65) or 1


def rows(entries: Iterable[Entry]) -> list[LogRow]:
    """Entries as the store keeps them."""
    return [LogRow(e.index, e.term, e.kind.value, e.data) for e in entries]


def state_of(kept: RaftRecord) -> PersistentState:
    """What a node restarts from, as the store kept it."""
    snapshot = Snapshot(
        kept.snap_index, kept.snap_term, Config.decode(kept.snap_config or b";"), kept.snap_data
    )
    entries = tuple(Entry(e.term, e.index, EntryKind(e.kind), e.data) for e in kept.entries)
    return PersistentState(HardState(kept.term, kept.vote, kept.commit), snapshot, entries)


def to_wire(chunk: ChunkId, m: Message) -> RaftMessage:
    """A core message of `chunk`'s group as it travels."""
    snap = m.snapshot
    return RaftMessage(
        chunk=chunk,
        kind=m.kind.value,
        sender=m.sender,
        to=m.to,
        term=m.term,
        log_term=m.log_term,
        index=m.index,
        entries=tuple(RaftEntry(e.term, e.index, e.kind.value, e.data) for e in m.entries),
        commit=m.commit,
        reject=m.reject,
        reject_hint=m.reject_hint,
        has_snapshot=snap is not None,
        snap_index=snap.index if snap else 0,
        snap_term=snap.term if snap else 0,
        snap_config=snap.config.encode() if snap else b"",
        snap_data=snap.data if snap else b"",
        context=m.context,
    )


def from_wire(w: RaftMessage) -> Message:
    """The core's message (ValueError for an unknown kind: the envelope decoder's
    ProtocolError path has already bounded every field)."""
    snapshot = (
        Snapshot(w.snap_index, w.snap_term, Config.decode(w.snap_config), w.snap_data)
        if w.has_snapshot
        else None
    )
    return Message(
        MessageKind(w.kind),
        w.sender,
        w.to,
        w.term,
        w.log_term,
        w.index,
        tuple(Entry(e.term, e.index, EntryKind(e.kind), e.data) for e in w.entries),
        w.commit,
        w.reject,
        w.reject_hint,
        snapshot,
        w.context,
    )
