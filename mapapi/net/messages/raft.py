"""One Raft group per chunk (DESIGN §13): its messages, batched per peer, and
proposals forwarded to the leader.

Plain frozen dataclasses, each mapping field by field onto the message of the
same name in `proto/mapapi/v1/wire.proto` (see `mapapi.net.messages`).
"""

from __future__ import annotations

from dataclasses import dataclass

from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, PeerId


@dataclass(frozen=True, slots=True)
class RaftEntry:
    """A log entry on the wire (`kind`: `raft_types.EntryKind`'s value)."""

    term: int
    index: int
    kind: int
    data: bytes


@dataclass(frozen=True, slots=True)
class RaftMessage:
    """One message of the chunk's group, between two node ids (see `swarm/groups.py`)."""

    chunk: ChunkId
    kind: int
    sender: int
    to: int
    term: int
    log_term: int
    index: int
    entries: tuple[RaftEntry, ...]
    commit: int
    reject: bool
    reject_hint: int
    has_snapshot: bool
    snap_index: int
    snap_term: int
    snap_config: bytes
    snap_data: bytes
    context: bytes


@dataclass(frozen=True, slots=True)
class RaftBatch:
    """All a peer has for another from every group they share, as one notification."""

    messages: tuple[RaftMessage, ...]


@dataclass(frozen=True, slots=True)
class RaftPropose:
    """Ask the chunk's leader to propose an encoded `Proposal` and wait for it."""

    chunk: ChunkId
    proposal: bytes


@dataclass(frozen=True, slots=True)
class RaftProposed:
    """The entry applied at the leader: its commit (None: it wrote nothing); for a
    prepare, the time it reserved (`prepared`) or that the chunk is `busy`; for
    an entry of a multi-chunk transaction the chunk decided, that decision."""

    record: CommitRecord | None
    revisions: tuple[Revision, ...]
    prepared: int = 0
    busy: bool = False
    decided: bool = False
    commit: bool = False
    time: int = 0


@dataclass(frozen=True, slots=True)
class ChainHead:
    """The leader's hash-chain link of the chunk's `count`-th commit (for comparison)."""

    chunk: ChunkId
    count: int
    link: bytes


@dataclass(frozen=True, slots=True)
class GroupJoin:
    """Ask the chunk's group to take the sender in as a holder."""

    chunk: ChunkId


@dataclass(frozen=True, slots=True)
class GroupLeave:
    """Ask the chunk's group to let the sender go."""

    chunk: ChunkId


@dataclass(frozen=True, slots=True)
class GroupChanged:
    """The group's members after the change, and the log index that made them so;
    from a member that does not lead, index 0 and the `leader` to ask (None: an
    election runs). `added`: the joiner was no member before (it starts over)."""

    index: int
    members: tuple[PeerId, ...] = ()
    leader: PeerId | None = None
    added: bool = False


BODIES: dict[str, type] = {
    "raft_batch": RaftBatch,
    "raft_propose": RaftPropose,
    "raft_proposed": RaftProposed,
    "chain_head": ChainHead,
    "group_join": GroupJoin,
    "group_leave": GroupLeave,
    "group_changed": GroupChanged,
}
"""Envelope body field -> class, for the messages of this area."""
