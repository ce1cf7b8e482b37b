"""The per-chunk reader-writer lock held by every holder (pure state machine).

DESIGN §6: a writer asks the arbiter (the lowest holder) first and, once
granted, the other holders in parallel. Each holder runs this state machine
for each chunk it holds: one writer at a time, local readers, a FIFO queue of
waiting writers (no busy retry), and leases. A grant carries a fencing token
(the holder's lock epoch for the chunk); commit and unlock messages must carry
it, and a stale token is refused. A lease not renewed by its deadline expires,
so a crashed writer cannot freeze the chunk. Time is a parameter (`now`).

A lease under which a commit batch is staged here is *pinned*: it does not
expire, because the writer may already have applied the commit elsewhere, and
letting another writer in would let this replica go on without it. A pinned
lease past its deadline is *overdue*: the holder asks the writer how the
commit ended (`mapapi.swarm.recovery`), or the writer's eviction settles it and
`preempt` takes the lock from the dead writer.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Collection
from dataclasses import dataclass, field, replace

from mapapi.core.errors import LockNotHeld
from mapapi.core.ids import PeerId

DEFAULT_LEASE = 5.0


@dataclass(frozen=True, slots=True)
class Grant:
    """A write lease: who holds it, its fencing token and when it expires
    (unless `pinned` by a staged commit batch)."""

    writer: PeerId
    token: int
    expires: float
    pinned: bool = False

    def overdue(self, now: float) -> bool:
        """A pinned lease past its deadline: its commit's outcome is in doubt here."""
        return self.pinned and self.expires <= now


@dataclass
class ChunkLock:
    """Lock state of one chunk on one holder."""

    lease: float = DEFAULT_LEASE
    readers: int = 0
    grant: Grant | None = None
    epoch: int = 0
    queue: deque[PeerId] = field(default_factory=deque)

    # -- writers ----------------------------------------------------------------
    def request(self, writer: PeerId, now: float) -> Grant | None:
        """Ask for the write lock.

        Returns:
            The grant if given now; None if queued. A writer that already
            holds the lock gets it again with the same token and a renewed
            lease, so requests may be retried and re-sending one renews.
        """
        self.expire(now)
        if self.grant is not None and self.grant.writer == writer:
            self.grant = replace(self.grant, expires=now + self.lease)
            return self.grant
        if writer not in self.queue:
            self.queue.append(writer)
        return self._promote(now)

    def cancel(self, writer: PeerId) -> None:
        """Withdraw a queued request (the writer gave up waiting)."""
        if writer in self.queue:
            self.queue.remove(writer)

    def release(self, writer: PeerId, token: int, now: float) -> Grant | None:
        """Release the write lock; returns the next grant, if one is made.

        Raises:
            LockNotHeld: `writer` does not hold the lock under `token`.
        """
        self.check(writer, token, now)
        self.grant = None
        return self._promote(now)

    def renew(self, writer: PeerId, token: int, now: float) -> Grant:
        """Extend a lease by `lease` seconds from `now`."""
        self.check(writer, token, now)
        assert self.grant is not None
        self.grant = replace(self.grant, expires=now + self.lease)
        return self.grant

    def pin(self, writer: PeerId, token: int, now: float) -> None:
        """Keep the lease from expiring: a batch of the writer's commit is staged.

        Raises:
            LockNotHeld: `writer` does not hold the lock under `token`.
        """
        self.check(writer, token, now)
        assert self.grant is not None
        self.grant = replace(self.grant, pinned=True)

    def preempt(self, writers: Collection[PeerId], now: float) -> Grant | None:
        """Take the lock from `writers` (declared dead), pinned or not, and drop
        their queued requests; returns the grant made to the next in line."""
        for writer in writers:
            self.cancel(writer)
        if self.grant is not None and self.grant.writer in writers:
            self.grant = None
            return self._promote(now)
        return None

    def check(self, writer: PeerId, token: int, now: float) -> None:
        """Refuse a message from a writer whose lease is gone or stale.

        Raises:
            LockNotHeld: no current grant to `writer` with `token`.
        """
        self.expire(now)
        if self.grant is None or self.grant.writer != writer or self.grant.token != token:
            holder = f"held by {self.grant.writer.short}" if self.grant else "free"
            raise LockNotHeld(
                f"stale lock token {token} from {writer.short} (lock is {holder}, "
                f"epoch {self.epoch}); the lease expired or was never granted"
            )

    def expire(self, now: float) -> Grant | None:
        """Drop an expired lease (never a pinned one); returns the grant made to
        the next in line."""
        if self.grant is not None and not self.grant.pinned and self.grant.expires <= now:
            self.grant = None
            return self._promote(now)
        return None

    # -- local readers ------------------------------------------------------------
    def readable(self, now: float) -> bool:
        """True when a local read may proceed (no writer holds the lock)."""
        self.expire(now)
        return self.grant is None

    def acquire_read(self, now: float) -> bool:
        """Take a local read lock if no writer holds the chunk."""
        if not self.readable(now):
            return False
        self.readers += 1
        return True

    def release_read(self, now: float) -> Grant | None:
        """Drop a local read lock; may let a queued writer in."""
        if self.readers <= 0:
            raise LockNotHeld("release_read without a read lock")
        self.readers -= 1
        return self._promote(now)

    # -- internals ------------------------------------------------------------------
    def _promote(self, now: float) -> Grant | None:
        """Grant the head of the queue if the chunk is free of readers and writers."""
        if self.grant is not None or self.readers or not self.queue:
            return None
        self.epoch += 1
        self.grant = Grant(self.queue.popleft(), self.epoch, now + self.lease)
        return self.grant


class LockTable:
    """The `ChunkLock`s of every chunk a peer holds, created on first use."""

    def __init__(self, lease: float = DEFAULT_LEASE) -> None:
        self.lease = lease
        self._locks: dict[str, ChunkLock] = {}

    def __getitem__(self, chunk: str) -> ChunkLock:
        lock = self._locks.get(chunk)
        if lock is None:
            lock = self._locks[chunk] = ChunkLock(self.lease)
        return lock

    def held_by(self, writer: PeerId) -> list[str]:
        """The chunks whose lock `writer` holds here."""
        return [c for c, lock in self._locks.items() if lock.grant and lock.grant.writer == writer]

    def get(self, chunk: str) -> ChunkLock | None:
        """A chunk's lock if it has one (without creating it: a message about a
        chunk nobody locked here must leave no state behind)."""
        return self._locks.get(chunk)

    def drop(self, chunk: str) -> None:
        """Forget a chunk's lock (the peer left the chunk)."""
        self._locks.pop(chunk, None)
