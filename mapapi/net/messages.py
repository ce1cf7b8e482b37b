"""The bodies of swarm messages (DESIGN §5-6): plain frozen dataclasses.

Each class maps field by field onto the message of the same name in
`proto/mapapi/v1/wire.proto`; `mapapi.net.codec` converts them generically.
Field types are limited to what that converter knows: ids, str, int, float,
bool, `Member`, `TableInfo`, `Revision`, `CommitRecord`, and tuples of those.
"""

from __future__ import annotations

from dataclasses import dataclass

from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId


@dataclass(frozen=True, slots=True)
class Member:
    """A peer of the swarm and the address others reach it at."""

    id: PeerId
    address: str
    name: str = ""


@dataclass(frozen=True, slots=True)
class TableInfo:
    """A table's name and full protobuf type name."""

    name: str
    type_name: str


@dataclass(frozen=True, slots=True)
class Ack:
    """Success with nothing to return."""


@dataclass(frozen=True, slots=True)
class LockRequest:
    """Ask for a chunk's write lock (the writer is the envelope's sender).

    `token` 0 asks for the lock; a token renews that lease only, and is refused
    with LockNotHeld once the lease is gone (never queued again).
    """

    chunk: ChunkId
    token: int = 0


@dataclass(frozen=True, slots=True)
class LockGrant:
    """A write lease with its fencing token; `lease` in seconds."""

    chunk: ChunkId
    token: int
    lease: float


@dataclass(frozen=True, slots=True)
class Unlock:
    """Release the lock (token 0: withdraw a request still waiting)."""

    chunk: ChunkId
    token: int


@dataclass(frozen=True, slots=True)
class CommitBatch:
    """One chunk's revisions of a commit, to stage under the lock."""

    chunk: ChunkId
    token: int
    record: CommitRecord
    revisions: tuple[Revision, ...]


@dataclass(frozen=True, slots=True)
class CommitApply:
    """Apply the staged batch atomically and release the lock."""

    chunk: ChunkId
    token: int
    commit_id: CommitId


@dataclass(frozen=True, slots=True)
class CommitAbort:
    """Drop the staged batch and release the lock."""

    chunk: ChunkId
    token: int
    commit_id: CommitId


@dataclass(frozen=True, slots=True)
class ParticipateRequest:
    """Newcomer to holder: make me a holder of `chunk`."""

    chunk: ChunkId


@dataclass(frozen=True, slots=True)
class ChunkPart:
    """One part of a chunk's full state, sent to a newcomer under the lock."""

    chunk: ChunkId
    table: TableInfo
    holders: tuple[Member, ...]
    revisions: tuple[Revision, ...]
    commits: tuple[CommitRecord, ...]
    part: int
    parts: int


@dataclass(frozen=True, slots=True)
class HolderChange:
    """A holder joined (or left) the chunk; sent under the chunk's lock."""

    chunk: ChunkId
    token: int
    member: Member
    joined: bool


@dataclass(frozen=True, slots=True)
class HoldersQuery:
    """Who holds `chunk`, or (chunk None) the chunk that holds `item`?"""

    chunk: ChunkId | None
    item: ItemId | None


@dataclass(frozen=True, slots=True)
class Holders:
    """The answer to `HoldersQuery`; empty when the asked peer does not know."""

    chunk: ChunkId | None
    table: str
    holders: tuple[Member, ...]


@dataclass(frozen=True, slots=True)
class Hello:
    """A peer introduces itself; answered with `Welcome`. `index` is the
    fingerprint of its spatial index geometry, which must equal the member's."""

    member: Member
    index: str = ""


@dataclass(frozen=True, slots=True)
class Welcome:
    """Every member the answering peer knows, itself included."""

    members: tuple[Member, ...]


@dataclass(frozen=True, slots=True)
class Bye:
    """The sender leaves the swarm gracefully."""


@dataclass(frozen=True, slots=True)
class ControlCall:
    """The CLI asks the running peer to perform one `mapapi.service.ops` operation,
    proving with `token` that it runs as the daemon's owner."""

    op: str
    args_json: str
    token: str = ""


@dataclass(frozen=True, slots=True)
class ControlResult:
    """The JSON result of a `ControlCall`."""

    json: str


# -- the Chord ring (DESIGN §7); ring keys travel as 20 big-endian bytes -------------


@dataclass(frozen=True, slots=True)
class ChordPeer:
    """A node of the ring: its key (20 bytes) and its Rpc address."""

    key: bytes
    address: str


@dataclass(frozen=True, slots=True)
class ChordFindSuccessor:
    """One step of an iterative lookup of `key`, ignoring the nodes in `avoid`."""

    key: bytes
    avoid: tuple[bytes, ...] = ()


@dataclass(frozen=True, slots=True)
class ChordHop:
    """`node` is the successor of the key (`final`) or the next node to ask."""

    node: ChordPeer
    final: bool


@dataclass(frozen=True, slots=True)
class ChordGetNeighbours:
    """Ask a node for its predecessor and successor list (also a liveness probe)."""


@dataclass(frozen=True, slots=True)
class ChordNeighbours:
    """A node's predecessor (zero or one) and successor list."""

    predecessor: tuple[ChordPeer, ...]
    successors: tuple[ChordPeer, ...]


@dataclass(frozen=True, slots=True)
class ChordNotify:
    """`node` thinks it might be the receiver's predecessor (Chord Fig. 7)."""

    node: ChordPeer


@dataclass(frozen=True, slots=True)
class ChordLeave:
    """`node` leaves gracefully; its predecessor (zero or one) and successors."""

    node: ChordPeer
    predecessor: tuple[ChordPeer, ...]
    successors: tuple[ChordPeer, ...]


@dataclass(frozen=True, slots=True)
class ChordAdd:
    """Add `member` to the set under `key` for `ttl` seconds (atomic at the owner)."""

    key: bytes
    member: bytes
    ttl: float
    replica: bool = False


@dataclass(frozen=True, slots=True)
class ChordRemove:
    """Remove `member` from the set under `key`."""

    key: bytes
    member: bytes
    replica: bool = False


@dataclass(frozen=True, slots=True)
class ChordGet:
    """The live members under `key`; with `filter`, those the node's filter of
    that name keeps for `argument`."""

    key: bytes
    filter: str = ""
    argument: bytes = b""


@dataclass(frozen=True, slots=True)
class ChordValues:
    """The answer to `ChordGet`."""

    members: tuple[bytes, ...]


@dataclass(frozen=True, slots=True)
class ChordEntry:
    """One stored member and the seconds it has left."""

    key: bytes
    member: bytes
    ttl: float


@dataclass(frozen=True, slots=True)
class ChordStore:
    """Entries to store; with `replicate` the receiver owns them and copies them on."""

    entries: tuple[ChordEntry, ...]
    replicate: bool = False


# -- lookup by peer (DESIGN §7) ----------------------------------------------------------


@dataclass(frozen=True, slots=True)
class ChunkListQuery:
    """Which chunks do you hold (of `table`, or of every table when empty)?"""

    table: str = ""


@dataclass(frozen=True, slots=True)
class ChunkSummary:
    """One chunk a peer holds: its id, table and number of live items."""

    chunk: ChunkId
    table: str
    items: int


@dataclass(frozen=True, slots=True)
class ChunkList:
    """The answer to `ChunkListQuery`."""

    chunks: tuple[ChunkSummary, ...]


@dataclass(frozen=True, slots=True)
class TriggerPush:
    """The revisions of one commit that match a subscription, for its subscriber."""

    subscription: bytes
    record: CommitRecord
    revisions: tuple[Revision, ...]
    tables: tuple[TableInfo, ...] = ()


@dataclass(frozen=True, slots=True)
class CommitStatusQuery:
    """How did these commits to `chunk` end at the receiver?"""

    chunk: ChunkId
    commit_ids: tuple[CommitId, ...]


@dataclass(frozen=True, slots=True)
class CommitStatus:
    """Of the commits asked about: applied at the receiver, or still being
    committed by it; any other one was never applied there."""

    applied: tuple[CommitId, ...]
    pending: tuple[CommitId, ...] = ()


@dataclass(frozen=True, slots=True)
class StagedBatch:
    """A commit's revisions of one chunk, staged at a holder and not yet applied."""

    record: CommitRecord
    revisions: tuple[Revision, ...]


@dataclass(frozen=True, slots=True)
class EvictRequest:
    """Lock `chunk` for the sender, its evictor, taking the lock from `dead`."""

    chunk: ChunkId
    dead: tuple[PeerId, ...]


@dataclass(frozen=True, slots=True)
class EvictGrant:
    """The evictor's lease, and every batch staged at the granting holder."""

    chunk: ChunkId
    token: int
    staged: tuple[StagedBatch, ...]


@dataclass(frozen=True, slots=True)
class EvictCommit:
    """Under the evictor's lease: apply `apply`, drop the batches of `drop`,
    take `dead` out of the holder set, then release the lock."""

    chunk: ChunkId
    token: int
    dead: tuple[PeerId, ...]
    apply: tuple[StagedBatch, ...]
    drop: tuple[CommitId, ...]


@dataclass(frozen=True, slots=True)
class Evicted:
    """The receiver is no longer a holder of `chunk`: it fetches it again."""

    chunk: ChunkId


# -- one Raft group per chunk (DESIGN §13) -------------------------------------------


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
    """The proposal applied at the leader: its commit (None: it wrote nothing)."""

    record: CommitRecord | None
    revisions: tuple[Revision, ...]


SWARM_BODIES: dict[str, type] = {
    "ack": Ack,
    "lock_request": LockRequest,
    "lock_grant": LockGrant,
    "unlock": Unlock,
    "commit_batch": CommitBatch,
    "commit_apply": CommitApply,
    "commit_abort": CommitAbort,
    "participate": ParticipateRequest,
    "chunk_part": ChunkPart,
    "holder_change": HolderChange,
    "holders_query": HoldersQuery,
    "holders": Holders,
    "chord_find_successor": ChordFindSuccessor,
    "chord_hop": ChordHop,
    "chord_get_neighbours": ChordGetNeighbours,
    "chord_neighbours": ChordNeighbours,
    "chord_notify": ChordNotify,
    "chord_leave": ChordLeave,
    "chord_add": ChordAdd,
    "chord_remove": ChordRemove,
    "chord_get": ChordGet,
    "chord_values": ChordValues,
    "chord_store": ChordStore,
    "chunk_list_query": ChunkListQuery,
    "chunk_list": ChunkList,
    "trigger_push": TriggerPush,
    "hello": Hello,
    "welcome": Welcome,
    "bye": Bye,
    "control_call": ControlCall,
    "control_result": ControlResult,
    "commit_status_query": CommitStatusQuery,
    "commit_status": CommitStatus,
    "evict_request": EvictRequest,
    "evict_grant": EvictGrant,
    "evict_commit": EvictCommit,
    "evicted": Evicted,
    "raft_batch": RaftBatch,
    "raft_propose": RaftPropose,
    "raft_proposed": RaftProposed,
}
