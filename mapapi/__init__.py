"""mapapi: a decentralized, git-like map repository for robot swarms.

The public API: `Peer` (async facade), `Transaction`, value types and errors;
the application (`mapapi.app`): peers with the map tables' rules, the operation
table behind `mapctl`, its peer daemon and `clone`. `mapapi.sync` wraps `Peer`
for blocking scripts. `mapctl` imports only what this module exports.
"""

from mapapi.app import attach, memory_peer, open_peer, operations, peer_of, run_daemon, start_daemon
from mapapi.core.change import Change, Conflict, Op
from mapapi.core.errors import (
    AlreadyInitialisedError,
    ChunkBusy,
    ChunkError,
    ChunkNotFound,
    ConflictError,
    CorruptRepoError,
    ItemNotFound,
    LimitExceeded,
    LockError,
    LockTimeout,
    MapError,
    NetworkError,
    NoQuorum,
    NotARepoError,
    NotChunkLeader,
    NotParticipatingError,
    ProposalLost,
    RepoError,
    TransactionError,
    UnresolvedConflicts,
    UsageError,
    ViewClosedError,
    WatchTimeout,
)
from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId
from mapapi.core.table import TableDescriptor
from mapapi.core.transaction import Transaction
from mapapi.core.view import mapctl_in
from mapapi.lookup.spatial import BBox, SpatialGrid
from mapapi.maps.schema import MISSIONS, Mission
from mapapi.net.security import Security, key_text, parse_key
from mapapi.service.clone import Cloned, clone
from mapapi.service.control import RemoteOperations
from mapapi.service.daemon_process import stop_daemon
from mapapi.service.ops import Operations, call_polled, check_address
from mapapi.service.peer import Peer
from mapapi.service.repo import PeerRecord, Repository
from mapapi.store import ChunkInfo, Store

__all__ = [
    "MISSIONS",
    "AlreadyInitialisedError",
    "BBox",
    "Change",
    "ChunkBusy",
    "ChunkError",
    "ChunkId",
    "ChunkInfo",
    "ChunkNotFound",
    "Cloned",
    "CommitId",
    "CommitRecord",
    "Conflict",
    "ConflictError",
    "CorruptRepoError",
    "ItemId",
    "ItemNotFound",
    "LimitExceeded",
    "LockError",
    "LockTimeout",
    "MapError",
    "Mission",
    "NetworkError",
    "NoQuorum",
    "NotARepoError",
    "NotChunkLeader",
    "NotParticipatingError",
    "Op",
    "Operations",
    "Peer",
    "PeerId",
    "PeerRecord",
    "ProposalLost",
    "RemoteOperations",
    "RepoError",
    "Repository",
    "Revision",
    "Security",
    "SpatialGrid",
    "Store",
    "TableDescriptor",
    "Transaction",
    "TransactionError",
    "UnresolvedConflicts",
    "UsageError",
    "ViewClosedError",
    "WatchTimeout",
    "attach",
    "call_polled",
    "check_address",
    "clone",
    "key_text",
    "mapctl_in",
    "memory_peer",
    "open_peer",
    "operations",
    "parse_key",
    "peer_of",
    "run_daemon",
    "start_daemon",
    "stop_daemon",
]
