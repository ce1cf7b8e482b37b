"""The bodies of swarm messages (DESIGN §5-7, §13): plain frozen dataclasses, one
module per protocol area: `peers` (meeting, leaving, control calls), `holding`
(chunks and holders), `triggers` (pushes to subscribers), `chord` (the ring),
`raft` (a group per chunk).

Each class maps field by field onto the message of the same name in
`proto/mapapi/v1/wire.proto`; `mapapi.net.codec` converts them generically.
Field types are limited to what that converter knows: ids, str, int, float,
bool, `Member`, `TableInfo`, `Revision`, `CommitRecord`, and tuples of those.
"""

from __future__ import annotations

from mapapi.net.messages import chord, holding, peers, raft, triggers
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
from mapapi.net.messages.holding import (
    ChunkList,
    ChunkListQuery,
    ChunkSummary,
    Holders,
    HoldersQuery,
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
from mapapi.net.messages.triggers import TriggerPush

SWARM_BODIES: dict[str, type] = {
    **peers.BODIES,
    **holding.BODIES,
    **triggers.BODIES,
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
    "ChunkSummary",
    "ControlCall",
    "ControlResult",
    "GroupChanged",
    "GroupJoin",
    "GroupLeave",
    "Hello",
    "Holders",
    "HoldersQuery",
    "Member",
    "RaftBatch",
    "RaftEntry",
    "RaftMessage",
    "RaftPropose",
    "RaftProposed",
    "TableInfo",
    "TriggerPush",
    "Welcome",
]
