"""Recovery from failed peers: in-doubt commits, eviction of dead holders, and
taking a chunk back after an eviction (issue 7 §1-4; docs/design.md, Failures).

**In-doubt commits.** A holder that staged a commit batch pins the writer's
lease (`mapapi.swarm.lock`). If the apply never comes, the lease runs out pinned
("overdue") and the holder asks the writer how the commit ended: applied (the
writer applies before it tells anyone: its local apply decides), aborted, or
still pending. It applies or drops the batch accordingly and releases the lock.
If the writer does not answer, the chunk stays locked here until the writer
answers or is evicted.

**Eviction.** Once `Liveness` declares a holder dead, the lowest live holder
of each chunk it held evicts it, provided the live holders are a quorum of
the holder set (`mapapi.swarm.quorum`; otherwise nobody may act, and commits to the
chunk fail with a retriable error until the dead holder answers again):

1. it locks the chunk at every live holder with `EvictRequest`, which takes
   the lock from the dead (even a pinned lease) and returns the batches
   staged there;
2. for those batches it asks every live holder whether it applied the commit
   (`CommitStatusQuery`): a commit applied anywhere is applied everywhere,
   one applied nowhere is dropped. A commit the writer reported as done was
   applied by a quorum, and every quorum of live holders includes one of
   them, so no acknowledged commit is dropped;
3. `EvictCommit` makes every live holder settle the batches, take the dead
   out of its holder set and release the lock; the evictor settles last, so
   a round that fails part-way is simply run again at the next tick.

**Coming back.** The evictor remembers whom it evicted; when such a peer is
heard of again it is told (`Evicted`) and fetches the chunk anew, which
replaces its replica with the swarm's (dropping any commit the swarm never
decided). A peer restarted after a crash does the same for every shared chunk
when it rejoins.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Coroutine, Iterable, Sequence
from typing import Any

from mapapi.core.errors import MapError, NotParticipatingError, PeerUnavailable, UsageError
from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, CommitId, PeerId
from mapapi.net.messages import (
    Ack,
    CommitStatus,
    CommitStatusQuery,
    EvictCommit,
    Evicted,
    EvictGrant,
    EvictRequest,
    Holders,
    HoldersQuery,
    StagedBatch,
    Unlock,
)
from mapapi.net.rpc import Answers, Request, Rpc, ask_all
from mapapi.store.base import ReplicaStore
from mapapi.swarm.commit_check import check_batch
from mapapi.swarm.liveness import Liveness
from mapapi.swarm.lock import Grant
from mapapi.swarm.lock_client import LockService
from mapapi.swarm.membership import Members
from mapapi.swarm.quorum import is_quorum
from mapapi.swarm.replication import Replicator

log = logging.getLogger(__name__)

REJOIN_PATIENCE = 120.0
"""Seconds an evicted peer keeps trying to fetch a chunk again after it was told."""


class Recovery:
    """Settles in-doubt commits and evicts dead holders for one peer."""

    def __init__(
        self,
        rpc: Rpc,
        members: Members,
        locks: LockService,
        store: ReplicaStore,
        replicator: Replicator,
        liveness: Liveness,
    ) -> None:
        self.rpc = rpc
        self.members = members
        self.locks = locks
        self.store = store
        self.replicator = replicator
        self.liveness = liveness
        self.retry = liveness.options.interval
        self._tasks: dict[tuple[str, ...], asyncio.Task[None]] = {}
        self._evicted: dict[PeerId, set[ChunkId]] = {}
        self._stuck: dict[ChunkId, tuple[PeerId, ...]] = {}  # chunks without a quorum, logged
        self.evictions = 0  # holders evicted by this peer (for tests and benchmarks)
        for body, handler in (
            (CommitStatusQuery, self.rpc_commit_status_query),
            (EvictRequest, self.rpc_evict_request),
            (EvictCommit, self.rpc_evict_commit),
            (Evicted, self.rpc_evicted),
        ):
            rpc.register(body, handler)

    @property
    def me(self) -> PeerId:
        """This peer's id."""
        return self.members.me.id

    def _spawn(self, key: tuple[str, ...], work: Coroutine[Any, Any, None]) -> None:
        """Run `work` in the background unless work under the same key (what it
        does, to which chunk, for whom) runs already."""
        running = self._tasks.get(key)
        if running is not None and not running.done():
            work.close()
            return
        name = " ".join(key)
        task = asyncio.get_running_loop().create_task(work, name=name)
        self._tasks[key] = task
        task.add_done_callback(lambda t: self._finished(key, name, t))

    def _finished(self, key: tuple[str, ...], name: str, task: asyncio.Task[None]) -> None:
        if self._tasks.get(key) is task:
            del self._tasks[key]
        if not task.cancelled() and task.exception() is not None:
            log.warning("%s failed: %s", name, task.exception())

    # -- eviction ----------------------------------------------------------------------
    def tick(self) -> None:
        """Start evicting the dead holders of every chunk where this peer is the
        lowest live holder and the live holders are a quorum (called by
        `Liveness` every round, so a failed eviction is simply tried again)."""
        for chunk, holders in self.store.holdings().items():
            if self.me not in holders:
                continue
            dead = tuple(p for p in holders if p != self.me and self.liveness.is_dead(p))
            if not dead:
                self._stuck.pop(chunk, None)
                continue
            live = [p for p in holders if p not in dead]
            if not is_quorum(live, holders):
                if self._stuck.get(chunk) != dead:
                    self._stuck[chunk] = dead
                    log.warning(
                        "chunk %s: %d of its %d holders do not answer and the others are no "
                        "majority; commits to it wait until they answer again",
                        chunk.short,
                        len(dead),
                        len(holders),
                    )
                continue
            if min(live) == self.me:
                self._spawn(("evict", chunk), self.evict(chunk, dead))

    async def evict(self, chunk: ChunkId, dead: Sequence[PeerId]) -> None:
        """Take `dead` out of `chunk`'s holder set at every live holder, settling
        the commits they left in doubt (see the module docstring).

        Raises:
            MapError: a live holder refused or did not answer; nothing changed
                at this peer, and the next tick tries again.
        """
        live = [p for p in self.store.holders(chunk) if p not in dead]
        others = [p for p in live if p != self.me]
        await self.locks.take_turn(chunk)
        tokens: dict[PeerId, int] = {}  # the leases to give back if the round fails
        try:
            await self.locks.preempt(chunk, dead)
            grant = await self.locks.grant_local(chunk, self.me, self.locks.lock_timeout)
            tokens[self.me] = grant.token
            batches = {
                b.record.id: _wire(b.record, b.revisions) for b in self.replicator.staged(chunk)
            }
            answers = await self._ask_all(others, EvictRequest(chunk, tuple(dead)))
            for peer, answer in answers.ok.items():
                if isinstance(answer, EvictGrant):  # given back below if another refused
                    tokens[peer] = answer.token
                    batches.update((b.record.id, b) for b in answer.staged)
            for peer, error in answers.failed.items():
                if isinstance(error, NotParticipatingError):
                    self.not_holder(chunk, peer)  # we are the one who was evicted
            answers.raise_first()
            apply, drop = await self._decide(chunk, batches, others)
            settled = await self._ask_all(
                others, lambda p: EvictCommit(chunk, tokens[p], tuple(dead), apply, drop)
            )
            settled.raise_first()
            tokens = {self.me: tokens[self.me]}  # the others released with the EvictCommit
            self._settle(chunk, dead, apply, drop)
        finally:
            await self._release(chunk, tokens)
            self.locks.end_turn(chunk)
        self.evictions += len(dead)
        for peer in dead:
            self._evicted.setdefault(peer, set()).add(chunk)
        log.warning(
            "evicted %s from chunk %s (applied %d, dropped %d commits in doubt)",
            ", ".join(p.short for p in dead),
            chunk.short,
            len(apply),
            len(drop),
        )

    async def _ask_all(self, peers: Sequence[PeerId], body: Any) -> Answers[PeerId, object]:
        """Send each peer `body` (or `body(peer)`) and wait for every answer (or failure)."""

        async def ask(peer: PeerId) -> object:
            message = body(peer) if callable(body) else body
            timeout = self.locks.lock_timeout + 1.0
            return await self.rpc.request(self.members.address(peer), message, timeout=timeout)

        return await ask_all({p: ask(p) for p in peers})

    async def _decide(
        self, chunk: ChunkId, batches: dict[CommitId, StagedBatch], others: Sequence[PeerId]
    ) -> tuple[tuple[StagedBatch, ...], tuple[CommitId, ...]]:
        """Which in-doubt commits to apply (applied by some live holder) and which
        to drop (applied by none), asking every live holder.

        Raises:
            MapError: a holder did not answer.
            PeerUnavailable: a holder is still committing one of them (try later).
        """
        if not batches:
            return (), ()
        ids = tuple(sorted(batches))
        answers = await self._ask_all(others, CommitStatusQuery(chunk, ids))
        answers.raise_first()
        applied = {c for c in ids if self.replicator.applied_here(chunk, c)}
        for answer in answers.ok.values():
            assert isinstance(answer, CommitStatus)
            if answer.pending:
                raise PeerUnavailable(
                    f"a holder of {chunk.short} is still committing",
                    advice="retry now: the commit completes or is dropped within a lease",
                )
            applied.update(answer.applied)
        apply = sorted((batches[c] for c in ids if c in applied), key=lambda b: b.record.time)
        return tuple(apply), tuple(c for c in ids if c not in applied)

    def _settle(
        self,
        chunk: ChunkId,
        dead: Sequence[PeerId],
        apply: Sequence[StagedBatch],
        drop: Sequence[CommitId],
    ) -> None:
        """Apply and drop the in-doubt batches here, and take `dead` out of the
        holder set (idempotent: a round that is run again changes nothing more)."""
        for batch in apply:
            if not self.replicator.applied_here(chunk, batch.record.id):
                # as if its writer had sent it: an evictor must not write anything else
                check_batch(self.store, chunk, batch.record, batch.revisions, batch.record.author)
                self.replicator.apply_batch(batch.record, batch.revisions)
            self.replicator.unstage(chunk, batch.record.id)
        for commit_id in drop:
            self.replicator.unstage(chunk, commit_id)
        holders = self.store.holders(chunk)
        if set(dead) & set(holders):
            self.store.set_holders(chunk, [p for p in holders if p not in dead])
        for peer in dead:  # a writer waiting on one of them now locks the new holder set
            self.liveness.mark_down(peer)

    async def _release(self, chunk: ChunkId, tokens: dict[PeerId, int]) -> None:
        """Release the leases an eviction round holds (best effort: a lease that is
        not given back runs out)."""
        for peer, token in tokens.items():
            try:
                if peer == self.me:
                    await self.locks.release_local(chunk, self.me, token)
                else:
                    await self.rpc.request(
                        self.members.address(peer), Unlock(chunk, token), expect=Ack
                    )
            except MapError as exc:
                log.debug("releasing %s at %s after an eviction: %s", chunk.short, peer, exc)

    # -- the live holders' side -----------------------------------------------------------
    async def rpc_evict_request(self, req: Request) -> EvictGrant:
        """Lock a chunk for its evictor, taking the lock from the dead, and hand
        over the batches staged here. Refused while a peer said to be dead still
        answers here (an evictor with a bad link must not evict a live holder)."""
        body: EvictRequest = req.body
        self.replicator.admit(body.chunk, req.sender)
        if self.me in body.dead:
            raise UsageError(f"{req.sender.short} takes this peer for dead, but it answers")
        holders = self.store.holders(body.chunk)
        alive = [p for p in body.dead if p in holders and self.liveness.answers(p)]
        if alive:
            raise PeerUnavailable(
                f"{', '.join(p.short for p in alive)} still answers here; not evicting it"
            )
        await self.locks.preempt(body.chunk, body.dead)
        grant = await self.locks.grant_local(body.chunk, req.sender, self.locks.lock_timeout)
        staged = tuple(_wire(b.record, b.revisions) for b in self.replicator.staged(body.chunk))
        return EvictGrant(body.chunk, grant.token, staged)

    async def rpc_evict_commit(self, req: Request) -> Ack:
        """Settle an eviction under the evictor's lease, then release it."""
        body: EvictCommit = req.body
        self.locks.check(body.chunk, req.sender, body.token)
        self._settle(body.chunk, body.dead, body.apply, body.drop)
        await self.locks.release_local(body.chunk, req.sender, body.token)
        return Ack()

    def rpc_commit_status_query(self, req: Request) -> CommitStatus:
        """Which of the commits asked about are applied here, or still being committed."""
        body: CommitStatusQuery = req.body
        return CommitStatus(
            tuple(c for c in body.commit_ids if self.replicator.applied_here(body.chunk, c)),
            tuple(c for c in body.commit_ids if c in self.replicator.committing),
        )

    # -- in-doubt commits ---------------------------------------------------------------------
    def overdue(self, chunk: ChunkId, grant: Grant) -> None:
        """A lease pinned by a staged batch ran out (told by `LockService`): ask
        its writer how the commit ended, in the background (`resolve`)."""
        self._spawn(("resolve", chunk), self.resolve(chunk, grant))

    async def resolve(self, chunk: ChunkId, grant: Grant) -> None:
        """Settle the batches staged under an overdue lease by asking their writer
        how each commit ended, then release the lease; gives up as soon as the
        lease is gone (an eviction took it)."""
        while self._current(chunk, grant):
            batches = [
                b
                for b in self.replicator.staged(chunk)
                if b.writer == grant.writer and b.token == grant.token
            ]
            if batches:
                try:
                    status = await self.rpc.request(
                        self.members.address(grant.writer),
                        CommitStatusQuery(chunk, tuple(b.record.id for b in batches)),
                        timeout=self.liveness.options.dead_after,
                        expect=CommitStatus,
                    )
                except MapError as exc:
                    log.info("commit in doubt on %s: its writer: %s", chunk.short, exc)
                    await asyncio.sleep(self.retry)
                    continue
                if not self._current(chunk, grant):
                    return
                for batch in batches:
                    commit_id = batch.record.id
                    if commit_id in status.applied:
                        self._settle(chunk, (), (_wire(batch.record, batch.revisions),), ())
                    elif commit_id not in status.pending:
                        self.replicator.unstage(chunk, commit_id)
                if any(b.record.id in status.pending for b in batches):
                    await asyncio.sleep(self.retry)
                    continue
            await self.locks.release_local(chunk, grant.writer, grant.token)
            return

    def _current(self, chunk: ChunkId, grant: Grant) -> bool:
        now = self.locks.table[chunk].grant
        return now is not None and (now.writer, now.token) == (grant.writer, grant.token)

    # -- evicted peers coming back ----------------------------------------------------------
    def evicted(self) -> Iterable[PeerId]:
        """The peers this one evicted and has not told yet (watched to see them back)."""
        return self._evicted.keys()

    def back(self, peer: PeerId) -> None:
        """`peer`, declared dead before, answers again: tell it of each chunk this
        peer evicted it from, so it fetches them again."""
        for chunk in sorted(self._evicted.pop(peer, set())):
            self._spawn(("tell", chunk, peer), self._tell_evicted(peer, chunk))

    async def _tell_evicted(self, peer: PeerId, chunk: ChunkId) -> None:
        try:
            await self.rpc.request(self.members.address(peer), Evicted(chunk), expect=Ack)
        except MapError:
            self._evicted.setdefault(peer, set()).add(chunk)  # tell it when it is back again
            raise

    def not_holder(self, chunk: ChunkId, holder: PeerId) -> None:
        """`holder` refused this peer as no holder of `chunk`: it was evicted and
        nobody told it (its evictor may be gone), so it fetches the chunk again
        once `holder` confirms."""
        if self.me in self.store.holders(chunk):
            self._spawn(("rejoin", chunk), self._rejoin(chunk, holder))

    def rpc_evicted(self, req: Request) -> Ack:
        """A holder evicted this peer from a chunk while it did not answer: fetch
        the chunk again (its replica may lack commits, or hold undecided ones)."""
        chunk: ChunkId = req.body.chunk
        holders = self.store.holders(chunk)
        if self.me in holders and req.sender in holders:
            self._spawn(("rejoin", chunk), self._rejoin(chunk, req.sender))
        return Ack()

    async def _rejoin(self, chunk: ChunkId, evictor: PeerId) -> None:
        """Fetch `chunk` again, once the evictor, asked at its own address, confirms
        that this peer is no longer a holder (a forged notice changes nothing).
        Retried every round for `REJOIN_PATIENCE` seconds: right after a partition
        heals, links may still come and go, and nobody sends the notice twice."""
        deadline = time.monotonic() + REJOIN_PATIENCE
        while True:
            try:
                answer = await self.rpc.request(
                    self.members.address(evictor), HoldersQuery(chunk, None), expect=Holders
                )
                if self.me in {m.id for m in answer.holders} or not answer.holders:
                    log.info("ignored a notice of eviction from %s it does not confirm", evictor)
                    return
                await self.replicator.participate(chunk, again=True)
            except MapError as exc:
                if time.monotonic() > deadline:
                    raise
                log.info("fetching chunk %s again failed (%s); retrying", chunk.short, exc)
                await asyncio.sleep(self.retry)
                continue
            log.warning("fetched chunk %s again after being evicted from it", chunk.short)
            return

    async def close(self) -> None:
        """Stop every background task."""
        tasks = list(self._tasks.values())
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        self._tasks.clear()


def _wire(record: CommitRecord, revisions: Sequence[Revision]) -> StagedBatch:
    return StagedBatch(record, tuple(revisions))
