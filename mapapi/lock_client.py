"""The distributed write lock of a chunk, over the network (DESIGN §6).

`LockService` drives the pure `ChunkLock` state machines of the chunks this
peer holds: it serves other writers' `LockRequest`s (a waiting request parks a
future, never the receive loop), expires leases on timers, and lets local
readers wait while a writer holds a chunk. As a client, `acquire` asks the
arbiter (the lowest holder) first and then every other holder in parallel, and
keeps the leases renewed until `release`.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

from mapapi.errors import LockNotHeld, LockTimeout, MapError
from mapapi.ids import ChunkId, PeerId
from mapapi.lock import Grant, LockTable
from mapapi.membership import Members
from mapapi.net.messages import Ack, LockGrant, LockRequest, Unlock
from mapapi.net.rpc import Request, Rpc

log = logging.getLogger(__name__)

DEFAULT_LOCK_TIMEOUT = 10.0


@dataclass
class Held:
    """The leases one writer holds on one chunk: holder -> fencing token."""

    chunk: ChunkId
    tokens: dict[PeerId, int] = field(default_factory=dict)


class LockService:
    """Serves and acquires chunk write locks for one peer."""

    def __init__(
        self,
        rpc: Rpc,
        members: Members,
        *,
        lease: float = 5.0,
        lock_timeout: float = DEFAULT_LOCK_TIMEOUT,
    ) -> None:
        self.rpc = rpc
        self.members = members
        self.table = LockTable(lease)
        self.lock_timeout = lock_timeout
        self._changed: dict[ChunkId, asyncio.Condition] = {}
        self._timers: dict[ChunkId, asyncio.TimerHandle] = {}
        self._renewals: dict[ChunkId, asyncio.Task[None]] = {}
        self._bookkeeping: set[asyncio.Task[None]] = set()
        # The state machine knows writers by peer id, so two writers of this
        # peer (two transactions, or a commit and a participation) take turns here.
        self._local_writers: dict[ChunkId, asyncio.Lock] = {}
        rpc.register(LockRequest, self.rpc_lock_request)
        rpc.register(Unlock, self.rpc_unlock)

    @property
    def me(self) -> PeerId:
        """This peer's id."""
        return self.members.me.id

    # -- the local state machine -----------------------------------------------
    def _condition(self, chunk: ChunkId) -> asyncio.Condition:
        cond = self._changed.get(chunk)
        if cond is None:
            cond = self._changed[chunk] = asyncio.Condition()
        return cond

    async def _notify(self, chunk: ChunkId) -> None:
        """Wake everyone waiting on the chunk's lock and re-arm its expiry timer."""
        lock = self.table[chunk]
        timer = self._timers.pop(chunk, None)
        if timer is not None:
            timer.cancel()
        if lock.grant is not None:
            loop = asyncio.get_running_loop()
            delay = max(0.0, lock.grant.expires - time.monotonic())
            self._timers[chunk] = loop.call_later(delay, self._expire_soon, chunk)
        cond = self._condition(chunk)
        async with cond:
            cond.notify_all()

    def _expire_soon(self, chunk: ChunkId) -> None:
        """Timer callback: drop the lease if it ran out, and wake the waiters."""
        self._timers.pop(chunk, None)
        self.table[chunk].expire(time.monotonic())
        task = asyncio.get_running_loop().create_task(self._notify(chunk))
        self._bookkeeping.add(task)
        task.add_done_callback(self._bookkeeping.discard)
        task.add_done_callback(_log_failure)

    async def grant_local(self, chunk: ChunkId, writer: PeerId, within: float) -> Grant:
        """Queue `writer` for the chunk's lock here and wait until it is granted.

        Raises:
            LockTimeout: not granted within `within` seconds (the request is withdrawn).
        """
        lock = self.table[chunk]
        cond = self._condition(chunk)
        try:
            async with asyncio.timeout(within), cond:
                grant = lock.request(writer, time.monotonic())
                while grant is None:
                    await cond.wait()
                    current = lock.grant
                    grant = current if current and current.writer == writer else None
        except TimeoutError:
            lock.cancel(writer)
            raise LockTimeout(
                f"chunk {chunk.short}: no write lock for {writer.short} within {within:g} s"
            ) from None
        await self._notify(chunk)
        return grant

    async def release_local(self, chunk: ChunkId, writer: PeerId, token: int) -> None:
        """Release (token > 0) or withdraw (token 0) `writer`'s lock here."""
        lock = self.table[chunk]
        if token == 0:
            lock.cancel(writer)
        else:
            lock.release(writer, token, time.monotonic())
        await self._notify(chunk)

    def check(self, chunk: ChunkId, writer: PeerId, token: int) -> None:
        """Refuse a commit message whose lease is not current (LockNotHeld)."""
        self.table[chunk].check(writer, token, time.monotonic())

    async def wait_readable(self, chunk: ChunkId) -> None:
        """Wait while a writer holds the chunk (local reads must not see a
        commit half-way: DESIGN §5)."""
        lock = self.table[chunk]
        if lock.readable(time.monotonic()):
            return
        cond = self._condition(chunk)
        try:
            async with asyncio.timeout(self.lock_timeout), cond:
                await cond.wait_for(lambda: lock.readable(time.monotonic()))
        except TimeoutError:
            raise LockTimeout(f"chunk {chunk.short} stayed write-locked; try again") from None

    # -- serving other writers ---------------------------------------------------
    async def rpc_lock_request(self, req: Request) -> LockGrant:
        """Grant a remote writer the lock once it is free here."""
        chunk = req.body.chunk
        grant = await self.grant_local(chunk, req.sender, self.lock_timeout)
        return LockGrant(chunk, grant.token, self.table.lease)

    async def rpc_unlock(self, req: Request) -> Ack:
        """Release or withdraw a remote writer's lock."""
        await self.release_local(req.body.chunk, req.sender, req.body.token)
        return Ack()

    # -- acquiring as a writer -------------------------------------------------------
    async def _acquire_one(self, chunk: ChunkId, holder: PeerId) -> int:
        if holder == self.me:
            return (await self.grant_local(chunk, self.me, self.lock_timeout)).token
        reply = await self.rpc.request(
            self.members.address(holder),
            LockRequest(chunk),
            timeout=self.lock_timeout + 1.0,
            expect=LockGrant,
        )
        return reply.token

    async def acquire(self, chunk: ChunkId, holders: Sequence[PeerId]) -> Held:
        """Write-lock `chunk` at every holder: the arbiter first, then the rest
        in parallel (two round trips, not one per holder).

        Raises:
            LockTimeout, NetworkError: a holder did not grant; nothing stays held.
        """
        ordered = sorted(set(holders))
        held = Held(chunk)
        turn = self._local_writers.setdefault(chunk, asyncio.Lock())
        try:
            async with asyncio.timeout(self.lock_timeout):
                await turn.acquire()
        except TimeoutError:
            raise LockTimeout(f"chunk {chunk.short}: another local writer kept it") from None
        try:
            held.tokens[ordered[0]] = await self._acquire_one(chunk, ordered[0])
            rest = ordered[1:]
            tokens = await asyncio.gather(
                *(self._acquire_one(chunk, h) for h in rest), return_exceptions=True
            )
            failures = [t for t in tokens if isinstance(t, BaseException)]
            for holder, token in zip(rest, tokens, strict=True):
                if isinstance(token, int):
                    held.tokens[holder] = token
            if failures:
                raise failures[0]
        except BaseException:
            await self.release(held, withdraw=ordered)
            raise

        self._renewals[chunk] = asyncio.get_running_loop().create_task(self._renew(held))
        return held

    async def _renew(self, held: Held) -> None:
        """Re-request every lease at a third of its length until released."""
        while True:
            await asyncio.sleep(self.table.lease / 3)
            for holder in held.tokens:
                try:
                    await self._acquire_one(held.chunk, holder)
                except MapError as exc:
                    log.warning(
                        "renewing the lease of %s at %s failed: %s", held.chunk, holder, exc
                    )

    async def release(self, held: Held, withdraw: Sequence[PeerId] = ()) -> None:
        """Unlock every holder in `held` (and withdraw requests at `withdraw`)."""
        renewal = self._renewals.pop(held.chunk, None)
        if renewal is not None:
            renewal.cancel()
        try:
            await self._unlock_all(held, withdraw)
        finally:
            self._local_writers[held.chunk].release()

    async def _unlock_all(self, held: Held, withdraw: Sequence[PeerId]) -> None:
        targets = {h: held.tokens.get(h, 0) for h in (*withdraw, *held.tokens)}
        results = await asyncio.gather(
            *(self._release_one(held.chunk, h, t) for h, t in targets.items()),
            return_exceptions=True,
        )
        for holder, result in zip(targets, results, strict=True):
            if isinstance(result, BaseException) and not isinstance(result, LockNotHeld):
                log.warning("unlocking %s at %s failed: %s", held.chunk, holder, result)

    async def _release_one(self, chunk: ChunkId, holder: PeerId, token: int) -> None:
        if holder == self.me:
            await self.release_local(chunk, self.me, token)
            return
        await self.rpc.request(self.members.address(holder), Unlock(chunk, token), expect=Ack)

    async def close(self) -> None:
        """Stop renewals and timers."""
        for task in self._renewals.values():
            task.cancel()
        await asyncio.gather(*self._renewals.values(), return_exceptions=True)
        self._renewals.clear()
        for timer in self._timers.values():
            timer.cancel()
        self._timers.clear()
        await asyncio.gather(*self._bookkeeping, return_exceptions=True)


def _log_failure(task: asyncio.Task[None]) -> None:
    if not task.cancelled() and task.exception() is not None:
        log.error("lock bookkeeping failed", exc_info=task.exception())
