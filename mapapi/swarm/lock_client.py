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
from collections.abc import Awaitable, Callable, Collection, Sequence
from dataclasses import dataclass, field

from mapapi.core.errors import (
    SETTLE_S,
    LockNotHeld,
    LockTimeout,
    MapError,
    NotParticipatingError,
    PeerUnavailable,
)
from mapapi.core.ids import ChunkId, PeerId
from mapapi.net.messages import Ack, LockGrant, LockRequest, Unlock
from mapapi.net.rpc import Request, Rpc
from mapapi.swarm.lock import ChunkLock, Grant, LockTable
from mapapi.swarm.membership import Members

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
        admit: Callable[[ChunkId, PeerId], None] | None = None,
        is_down: Callable[[PeerId], bool] | None = None,
        on_overdue: Callable[[ChunkId, Grant], None] | None = None,
        on_not_holder: Callable[[ChunkId, PeerId], None] | None = None,
    ) -> None:
        self.rpc = rpc
        # Who may ask for a chunk's lock (the swarm admits its holders only).
        self.admit = admit
        # Whether a holder is believed down (its requests fail fast instead of
        # waiting out their deadline), and who settles an overdue pinned lease.
        self.is_down: Callable[[PeerId], bool] = is_down or (lambda peer: False)
        self.on_overdue = on_overdue
        # Told when a holder refuses this peer as no holder of a chunk (it was evicted).
        self.on_not_holder = on_not_holder
        self.members = members
        self.table = LockTable(lease)
        self.lock_timeout = lock_timeout
        self._changed: dict[ChunkId, asyncio.Condition] = {}
        self._timers: dict[ChunkId, asyncio.TimerHandle] = {}
        self._renewals: dict[ChunkId, asyncio.Task[None]] = {}
        self._bookkeeping: set[asyncio.Task[None]] = set()
        self._closed = False
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

    def _arm_timer(self, chunk: ChunkId) -> None:
        """(Re-)arm the chunk's expiry timer for the current lease, if any."""
        timer = self._timers.pop(chunk, None)
        if timer is not None:
            timer.cancel()
        grant = self.table[chunk].grant
        now = time.monotonic()
        if grant is not None and not grant.overdue(now) and not self._closed:
            loop = asyncio.get_running_loop()
            delay = max(0.0, grant.expires - now)
            self._timers[chunk] = loop.call_later(delay, self._expire_soon, chunk)

    async def _notify(self, chunk: ChunkId) -> None:
        """Wake everyone waiting on the chunk's lock and re-arm its expiry timer."""
        self._arm_timer(chunk)
        cond = self._condition(chunk)
        async with cond:
            cond.notify_all()

    def _notify_soon(self, chunk: ChunkId) -> None:
        """`_notify` from code that cannot await (a timer, a cancelled waiter)."""
        if self._closed:
            return
        task = asyncio.get_running_loop().create_task(self._notify(chunk))
        self._bookkeeping.add(task)
        task.add_done_callback(self._bookkeeping.discard)
        task.add_done_callback(_log_failure)

    def _expire_soon(self, chunk: ChunkId) -> None:
        """Timer callback: drop the lease if it ran out, and wake the waiters."""
        self._timers.pop(chunk, None)
        lock = self.table[chunk]
        now = time.monotonic()
        lock.expire(now)
        if lock.grant is not None and lock.grant.overdue(now) and self.on_overdue is not None:
            self.on_overdue(chunk, lock.grant)
        self._notify_soon(chunk)

    async def grant_local(self, chunk: ChunkId, writer: PeerId, within: float) -> Grant:
        """Queue `writer` for the chunk's lock here and wait until it is granted.

        Raises:
            LockTimeout: not granted within `within` seconds (the request is withdrawn).
        """
        lock = self.table[chunk]
        cond = self._condition(chunk)
        token_before = lock.grant.token if lock.grant and lock.grant.writer == writer else 0
        try:
            async with asyncio.timeout(within), cond:
                grant = lock.request(writer, time.monotonic())
                while grant is None:
                    self._refuse_behind_the_dead(chunk, writer)
                    await cond.wait()
                    current = lock.grant
                    grant = current if current and current.writer == writer else None
        except BaseException as exc:
            # Timed out or cancelled (the requester left, the peer closes): withdraw
            # the request, and give back a grant made meanwhile that nobody will
            # use, or the chunk would stay locked until that lease ran out.
            lock.cancel(writer)
            current = lock.grant
            if current is not None and current.writer == writer and current.token != token_before:
                lock.release(writer, current.token, time.monotonic())
                self._notify_soon(chunk)
            if isinstance(exc, TimeoutError):
                raise LockTimeout(
                    f"chunk {chunk.short}: no write lock for {writer.short} within {within:g} s"
                ) from None
            raise
        await self._notify(chunk)
        return grant

    def _refuse_behind_the_dead(self, chunk: ChunkId, writer: PeerId) -> None:
        """Do not queue behind a writer that is down: only its eviction frees the
        lock, and a writer waiting here while it holds the arbiter's grant would
        keep the evictor out (raises PeerUnavailable, retriable)."""
        current = self.table[chunk].grant
        if current is not None and current.writer != writer and self.is_down(current.writer):
            raise PeerUnavailable(
                f"chunk {chunk.short} is locked by {self.members.label(current.writer)}, "
                "which does not answer"
            )

    def writer_down(self, peer: PeerId) -> None:
        """`peer` was declared down: wake the writers queued behind its locks, which
        then give up (`_refuse_behind_the_dead`)."""
        for chunk in self.table.held_by(peer):
            self._notify_soon(ChunkId(chunk))

    def renew_local(self, chunk: ChunkId, writer: PeerId, token: int) -> Grant:
        """Extend `writer`'s current lease here.

        Raises:
            LockNotHeld: the lease under `token` is gone (expired or released).
        """
        grant = self._existing(chunk, writer, token).renew(writer, token, time.monotonic())
        self._arm_timer(chunk)
        return grant

    def _existing(self, chunk: ChunkId, writer: PeerId, token: int) -> ChunkLock:
        """The chunk's lock; LockNotHeld if nobody ever locked it here."""
        lock = self.table.get(chunk)
        if lock is None:
            raise LockNotHeld(
                f"stale lock token {token} from {writer.short}: chunk {chunk.short} "
                "was never locked here"
            )
        return lock

    async def release_local(self, chunk: ChunkId, writer: PeerId, token: int) -> None:
        """Release (token > 0) or withdraw (token 0) `writer`'s lock here."""
        if token == 0 and self.table.get(chunk) is None:
            return  # nothing to withdraw
        lock = self._existing(chunk, writer, token)
        if token == 0:
            # The writer gave up before it saw a grant: a grant made meanwhile
            # is unused (its acquires take turns, so it holds nothing else here).
            lock.cancel(writer)
            if lock.grant is not None and lock.grant.writer == writer:
                lock.release(writer, lock.grant.token, time.monotonic())
        else:
            lock.release(writer, token, time.monotonic())
        await self._notify(chunk)

    def pin(self, chunk: ChunkId, writer: PeerId, token: int) -> None:
        """Pin `writer`'s lease: a batch of its commit is staged here (LockNotHeld
        if the lease is not current)."""
        self.table[chunk].pin(writer, token, time.monotonic())

    async def preempt(self, chunk: ChunkId, writers: Collection[PeerId]) -> None:
        """Take the chunk's lock from dead `writers` and drop their requests."""
        self.table[chunk].preempt(writers, time.monotonic())
        await self._notify(chunk)

    def check(self, chunk: ChunkId, writer: PeerId, token: int) -> None:
        """Refuse a commit message whose lease is not current (LockNotHeld)."""
        self._existing(chunk, writer, token).check(writer, token, time.monotonic())

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
        """Grant a remote writer the lock once it is free here, or renew its lease."""
        body: LockRequest = req.body
        if body.token:
            grant = self.renew_local(body.chunk, req.sender, body.token)
        else:
            if self.admit is not None:
                self.admit(body.chunk, req.sender)
            grant = await self.grant_local(body.chunk, req.sender, self.lock_timeout)
        return LockGrant(body.chunk, grant.token, self.table.lease)

    async def rpc_unlock(self, req: Request) -> Ack:
        """Release or withdraw a remote writer's lock."""
        await self.release_local(req.body.chunk, req.sender, req.body.token)
        return Ack()

    # -- acquiring as a writer -------------------------------------------------------
    async def _acquire_one(self, chunk: ChunkId, holder: PeerId) -> int:
        if holder == self.me:
            return (await self.grant_local(chunk, self.me, self.lock_timeout)).token
        if self.is_down(holder):
            raise PeerUnavailable(
                f"holder {self.members.label(holder)} of chunk {chunk.short} does not answer",
                advice=(
                    f"wait about {SETTLE_S} s and retry: the other holders evict it if they are a "
                    "majority; if not, wait for it to come back (`mapctl peers`)"
                ),
            )
        try:
            reply = await self.rpc.request(
                self.members.address(holder),
                LockRequest(chunk),
                timeout=self.lock_timeout + 1.0,
                expect=LockGrant,
            )
        except NotParticipatingError:
            if self.on_not_holder is not None:
                self.on_not_holder(chunk, holder)
            raise
        return reply.token

    async def _renew_one(self, chunk: ChunkId, holder: PeerId, token: int) -> None:
        if holder == self.me:
            self.renew_local(chunk, self.me, token)
            return
        await self.rpc.request(
            self.members.address(holder),
            LockRequest(chunk, token),
            timeout=self.table.lease / 3,
            expect=LockGrant,
        )

    async def acquire(
        self,
        chunk: ChunkId,
        holders: Sequence[PeerId],
        *,
        current: Callable[[], Sequence[PeerId]] | None = None,
        precheck: Callable[[], Awaitable[None]] | None = None,
    ) -> Held:
        """Write-lock `chunk` at every holder: the arbiter first, then the rest
        in parallel (two round trips, not one per holder).

        Args:
            holders: the chunk's holders as the caller last saw them.
            current: reads the holder set again. Holders join and leave only under
                the chunk's write lock, so once the arbiter granted, this peer's
                copy of the set is up to date; if it changed (a joiner may even
                be the new arbiter), the grants are handed back and the lock is
                taken again from the current holders, so a commit reaches every
                holder and no two writers disagree on the arbiter.
            precheck: awaited once the arbiter granted, before the others are asked;
                if it raises (a commit that the local replica already shows to be
                in conflict), only the arbiter's grant is handed back, which under
                contention saves a lock and an unlock at every other holder.

        Raises:
            LockTimeout, NetworkError: a holder did not grant; nothing stays held.
            Whatever `precheck` raises.
        """
        await self.take_turn(chunk)
        held = Held(chunk)
        ordered = sorted(set(holders))
        asked: Sequence[PeerId] = ordered[:1]  # where a request of ours may still wait
        try:
            while True:
                try:
                    held.tokens[ordered[0]] = await self._acquire_one(chunk, ordered[0])
                except MapError:
                    if not self._holders_changed(ordered, current):
                        raise
                else:
                    if not self._holders_changed(ordered, current):
                        if precheck is not None:
                            await precheck()  # raises: only the arbiter's grant goes back
                        asked = ordered
                        failure = await self._acquire_rest(held, ordered[1:])
                        if not self._holders_changed(ordered, current):
                            if failure is not None:
                                raise failure
                            break
                # A holder joined or left while we waited (a request to one that
                # left may even have failed): lock the current holders instead.
                assert current is not None
                log.debug("holders of %s changed while locking it; locking again", chunk)
                await self._unlock_all(held, asked)
                held = Held(chunk)
                ordered = sorted(set(current()))
                asked = ordered[:1]
        except BaseException:
            await self.release(held, withdraw=asked)
            raise

        self._renewals[chunk] = asyncio.get_running_loop().create_task(
            self._renew(held), name=f"renew lock {chunk.short}"
        )
        return held

    async def take_turn(self, chunk: ChunkId) -> None:
        """Wait until no other writer of this peer works on `chunk` (the lock
        knows writers by peer id, so this peer's own writers take turns here);
        `end_turn` lets the next one in.

        Raises:
            LockTimeout: another local writer kept the chunk for `lock_timeout`.
        """
        turn = self._local_writers.setdefault(chunk, asyncio.Lock())
        try:
            async with asyncio.timeout(self.lock_timeout):
                await turn.acquire()
        except TimeoutError:
            raise LockTimeout(f"chunk {chunk.short}: another local writer kept it") from None

    def end_turn(self, chunk: ChunkId) -> None:
        """Let the next local writer of `chunk` in (after `take_turn`)."""
        self._local_writers[chunk].release()

    async def _acquire_rest(self, held: Held, rest: Sequence[PeerId]) -> MapError | None:
        """Ask every holder but the arbiter in parallel; their tokens go into
        `held`. Returns the first failure (not raised: the caller decides)."""
        tokens = await asyncio.gather(
            *(self._acquire_one(held.chunk, h) for h in rest), return_exceptions=True
        )
        failure: MapError | None = None
        for holder, token in zip(rest, tokens, strict=True):
            if isinstance(token, int):
                held.tokens[holder] = token
            elif isinstance(token, MapError):
                failure = failure or token
            elif isinstance(token, BaseException):
                raise token
        return failure

    @staticmethod
    def _holders_changed(
        ordered: list[PeerId], current: Callable[[], Sequence[PeerId]] | None
    ) -> bool:
        return current is not None and sorted(set(current())) != ordered

    async def _renew(self, held: Held) -> None:
        """Renew every lease at a third of its length until released; a lease
        that is gone (expired, taken over) is not renewed again."""
        live = dict(held.tokens)
        while live:
            await asyncio.sleep(self.table.lease / 3)
            results = await asyncio.gather(
                *(self._renew_one(held.chunk, h, t) for h, t in live.items()),
                return_exceptions=True,
            )
            for holder, result in zip(list(live), results, strict=True):
                if isinstance(result, LockNotHeld):
                    log.warning("lost the lease of %s at %s: %s", held.chunk, holder, result)
                    del live[holder]
                elif isinstance(result, MapError):
                    log.warning(
                        "renewing the lease of %s at %s failed: %s", held.chunk, holder, result
                    )
                elif isinstance(result, BaseException):
                    raise result

    async def stop_renewing(self, held: Held) -> None:
        """Stop renewing `held`'s leases (before messages that end them)."""
        renewal = self._renewals.pop(held.chunk, None)
        if renewal is not None:
            renewal.cancel()
            await asyncio.gather(renewal, return_exceptions=True)

    async def release(self, held: Held, withdraw: Sequence[PeerId] = ()) -> None:
        """Unlock every holder in `held` (and withdraw requests at `withdraw`)."""
        try:
            await self.stop_renewing(held)
            await self._unlock_all(held, withdraw)
        finally:
            self.end_turn(held.chunk)

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
        self._closed = True
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
