"""The bodies of swarm messages (DESIGN §5-7, §13): plain frozen dataclasses, one
module per protocol area: `peers` (meeting, leaving, control calls), `holding`
(chunks and holders), `commit` (the lock, the batch, eviction), `chord` (the
ring), `raft` (a group per chunk).

Each class maps field by field onto the message of the same name in
`proto/mapapi/v1/wire.proto`; `mapapi.net.codec` converts them generically.
Field types are limited to what that converter knows: ids, str, int, float,
bool, `Member`, `TableInfo`, `Revision`, `CommitRecord`, and tuples of those.
"""

from __future__ import annotations

from mapapi.net.messages import chord, commit, holding, peers, raft
from mapapi.net.messages.chord import (
    ChordAdd,
    ChordEntry,
    ChordFindSuccessor,
    ChordGet,
    ChordGetNeighbours,
    ChordHop,
    ChordLeave,
    ChordNeighbours,
    ChordNotify,
    ChordPeer,
    ChordRemove,
    ChordStore,
    ChordValues,
)
from mapapi.net.messages.commit import (
    CommitAbort,
    CommitApply,
    CommitBatch,
    CommitStatus,
    CommitStatusQuery,
    EvictCommit,
    Evicted,
    EvictGrant,
    EvictRequest,
    LockGrant,
    LockRequest,
    StagedBatch,
    TriggerPush,
    Unlock,
)
from mapapi.net.messages.holding import (
    ChunkList,
    ChunkListQuery,
    ChunkPart,
    ChunkSummary,
    HolderChange,
    Holders,
    HoldersQuery,
    ParticipateRequest,
    TableInfo,
)
from mapapi.net.messages.peers import (
    Ack,
    Bye,
    ControlCall,
    ControlResult,
    Hello,
    Member,
    Welcome,
)
from mapapi.net.messages.raft import (
    ChainHead,
    GroupChanged,
    GroupJoin,
    GroupLeave,
    RaftBatch,
    RaftEntry,
    RaftMessage,
    RaftPropose,
    RaftProposed,
)

SWARM_BODIES: dict[str, type] = {
    **peers.BODIES,
    **holding.BODIES,
    **commit.BODIES,
    **chord.BODIES,
    **raft.BODIES,
}
"""Envelope body field -> class, for every swarm message (the codec registers them)."""

__all__ = [
    "SWARM_BODIES",
    "Ack",
    "Bye",
    "ChainHead",
    "ChordAdd",
    "ChordEntry",
    "ChordFindSuccessor",
    "ChordGet",
    "ChordGetNeighbours",
    "ChordHop",
    "ChordLeave",
    "ChordNeighbours",
    "ChordNotify",
    "ChordPeer",
    "ChordRemove",
    "ChordStore",
    "ChordValues",
    "ChunkList",
    "ChunkListQuery",
    "ChunkPart",
    "ChunkSummary",
    "CommitAbort",
    "CommitApply",
    "CommitBatch",
    "CommitStatus",
    "CommitStatusQuery",
    "ControlCall",
    "ControlResult",
    "EvictCommit",
    "EvictGrant",
    "EvictRequest",
    "Evicted",
    "GroupChanged",
    "GroupJoin",
    "GroupLeave",
    "Hello",
    "HolderChange",
    "Holders",
    "HoldersQuery",
    "LockGrant",
    "LockRequest",
    "Member",
    "ParticipateRequest",
    "RaftBatch",
    "RaftEntry",
    "RaftMessage",
    "RaftPropose",
    "RaftProposed",
    "StagedBatch",
    "TableInfo",
    "TriggerPush",
    "Unlock",
    "Welcome",
]
