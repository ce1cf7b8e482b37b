"""A commit under a chunk's write lock: the lock, the batch, its outcome, the
eviction of a dead holder, and the trigger push that follows.

Plain frozen dataclasses, each mapping field by field onto the message of the
same name in `proto/mapapi/v1/wire.proto` (see `mapapi.net.messages`).
"""

from __future__ import annotations

from dataclasses import dataclass

from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, CommitId, PeerId
from mapapi.net.messages.holding import TableInfo


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


@dataclass(frozen=True, slots=True)
class TriggerPush:
    """The revisions of one commit that match a subscription, for its subscriber."""

    subscription: bytes
    record: CommitRecord
    revisions: tuple[Revision, ...]
    tables: tuple[TableInfo, ...] = ()


BODIES: dict[str, type] = {
    "lock_request": LockRequest,
    "lock_grant": LockGrant,
    "unlock": Unlock,
    "commit_batch": CommitBatch,
    "commit_apply": CommitApply,
    "commit_abort": CommitAbort,
    "commit_status_query": CommitStatusQuery,
    "commit_status": CommitStatus,
    "evict_request": EvictRequest,
    "evict_grant": EvictGrant,
    "evict_commit": EvictCommit,
    "evicted": Evicted,
    "trigger_push": TriggerPush,
}
"""Envelope body field -> class, for the messages of this area."""
