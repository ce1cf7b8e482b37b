"""mapapi: a decentralized, git-like map repository for robot swarms.

The public API: `Peer` (async facade), `Transaction`, value types and errors.
`mapapi.sync` wraps `Peer` for blocking scripts.
"""

from mapapi.core.errors import (
    AlreadyInitialisedError,
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
    NotARepoError,
    NotParticipatingError,
    RepoError,
    TransactionError,
    UnresolvedConflicts,
    UsageError,
    ViewClosedError,
)
from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId
from mapapi.core.table import TableDescriptor
from mapapi.core.transaction import Change, Conflict, Op, Transaction
from mapapi.service.peer import Peer
from mapapi.service.repo import Repository
from mapapi.store import ChunkInfo

__all__ = [
    "AlreadyInitialisedError",
    "Change",
    "ChunkError",
    "ChunkId",
    "ChunkInfo",
    "ChunkNotFound",
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
    "NetworkError",
    "NotARepoError",
    "NotParticipatingError",
    "Op",
    "Peer",
    "PeerId",
    "RepoError",
    "Repository",
    "Revision",
    "TableDescriptor",
    "Transaction",
    "TransactionError",
    "UnresolvedConflicts",
    "UsageError",
    "ViewClosedError",
]
