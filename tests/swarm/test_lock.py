"""The distributed write lock across peers: leases, fencing tokens, readers
waiting for writers (DESIGN §5-6)."""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from mapapi import ChunkId, CommitId, CommitRecord, LockTimeout, Peer, PeerId
from mapapi.core.errors import LockNotHeld
from mapapi.net.messages import CommitApply, CommitBatch, HolderChange, LockRequest, Unlock
from mapapi.swarm.lock import Grant
from mapapi.swarm.lock_client import Held
from tests.swarm.conftest import (
    TABLE,
    Counter,
    MakeSwarm,
    counter_chunk,
    increment,
    net,
    value,
)


def _record(peer: Peer, chunk: ChunkId) -> CommitRecord:
    return CommitRecord(CommitId.new(), peer.now() + 1, peer.id, "stale", (chunk,))


class TestLeases:
    async def test_a_holder_that_stops_renewing_loses_the_lock(self, swarm: MakeSwarm) -> None:
        """A writer takes the lock and freezes (no renewals, no unlock): after
        its lease another peer commits, and the frozen writer's late messages,
        carrying its old fencing tokens, are refused."""
        a, b = await swarm(2, lease=0.3)
        chunk, item = await counter_chunk(a)
        await b.participate(chunk)
        frozen = await net(a).locks.acquire(chunk, a.holders(chunk))
        await net(a).locks.stop_renewing(frozen)  # as if the writer hung
        async with asyncio.timeout(5):  # well below the 10 s lock timeout
            assert await increment(b, [(TABLE, item)]) == 0
        assert await value(a, item) == 1
        assert await value(b, item) == 1

        # b now holds the lock itself; a's stale token must not touch it.
        current = await net(b).locks.acquire(chunk, b.holders(chunk))
        stale = frozen.tokens[b.id]
        assert current.tokens[b.id] > stale
        record = _record(a, chunk)
        for body in (
            CommitBatch(chunk, stale, record, ()),
            CommitApply(chunk, stale, record.id),
            HolderChange(chunk, stale, net(a).members.me, False),
            Unlock(chunk, stale),
            LockRequest(chunk, stale),  # a renewal of the lost lease
        ):
            with pytest.raises(LockNotHeld):
                await net(a).rpc.request(b.address, body)
        net(b).locks.check(chunk, b.id, current.tokens[b.id])  # still b's
        await net(b).locks.release(current)
        await net(a).locks.release(frozen)  # late and harmless
        assert await increment(a, [(TABLE, item)]) == 0
        assert await value(b, item) == 2

    async def test_renewals_keep_the_lock_past_its_lease(self, swarm: MakeSwarm) -> None:
        """While renewed, a lease of 0.4 s holds for a whole 1.2 s lock timeout."""
        a, b = await swarm(2, lease=0.4, lock_timeout=1.2)
        chunk, item = await counter_chunk(a)
        await b.participate(chunk)
        held = await net(a).locks.acquire(chunk, a.holders(chunk))
        with pytest.raises(LockTimeout):
            await net(b).locks.acquire(chunk, b.holders(chunk))
        await net(a).locks.release(held)
        assert await increment(b, [(TABLE, item)]) == 0
        assert await value(a, item) == 1

    async def test_a_writer_that_gives_up_waiting_leaves_no_lock_behind(
        self, swarm: MakeSwarm
    ) -> None:
        """A request that times out while queued is withdrawn everywhere: the
        next writer is not held up by a grant nobody will use."""
        a, b, c = await swarm(3, lock_timeout=0.5)
        chunk, item = await counter_chunk(a)
        await b.participate(chunk)
        await c.participate(chunk)
        held = await net(a).locks.acquire(chunk, a.holders(chunk))
        with pytest.raises(LockTimeout):
            await net(b).locks.acquire(chunk, b.holders(chunk))
        await net(a).locks.release(held)
        for peer in (a, b, c):
            net(peer).locks.lock_timeout = 10.0
        async with asyncio.timeout(2):  # not a lease (5 s) later
            assert await increment(c, [(TABLE, item)]) == 0
        for peer in (a, b, c):
            await net(peer).locks.wait_readable(chunk)  # c's apply+unlock has landed
            assert not net(peer).locks.table[chunk].queue
            assert net(peer).locks.table[chunk].grant is None

    async def test_a_writer_cancelled_while_it_waits_leaves_no_request_behind(
        self, swarm: MakeSwarm, monkeypatch: pytest.MonkeyPatch
    ) -> None:
        """The arbiter's own commit is cancelled (say, by its caller's timeout)
        while queued for its local grant: that request must go, or the arbiter
        would hold the chunk, unrenewed and unused, for a whole lease."""
        low, high = sorted(await swarm(2), key=lambda p: p.id)  # low is the arbiter
        chunk, item = await counter_chunk(high)
        await low.participate(chunk)
        held = await net(high).locks.acquire(chunk, high.holders(chunk))
        lock = net(low).locks.table[chunk]
        queued = asyncio.Event()
        real_request = lock.request

        def spy(writer: PeerId, now: float) -> Grant | None:
            grant = real_request(writer, now)
            queued.set()
            return grant

        monkeypatch.setattr(lock, "request", spy)
        waiter = asyncio.create_task(net(low).locks.acquire(chunk, low.holders(chunk)))
        async with asyncio.timeout(5):
            await queued.wait()
        assert list(lock.queue) == [low.id]
        waiter.cancel()
        with pytest.raises(asyncio.CancelledError):
            await waiter
        await net(high).locks.release(held)
        async with asyncio.timeout(2):  # the lease is 5 s
            assert await increment(high, [(TABLE, item)]) == 0
        assert await value(low, item) == 1

    async def test_a_commit_whose_lease_ran_out_is_refused_and_retriable(
        self, swarm: MakeSwarm, monkeypatch: pytest.MonkeyPatch
    ) -> None:
        """The writer stalls between validating and staging; its leases expire,
        another peer commits, and the stalled commit is refused by the holders'
        fencing: nothing of it is written and the caller may retry."""
        a, b = await swarm(2, lease=0.3)
        chunk, item = await counter_chunk(a)
        await b.participate(chunk)
        replicator = net(a).replicator
        real_push = replicator.push
        stalled, resume = asyncio.Event(), asyncio.Event()

        async def stalling_push(held: list[Held], *args: Any) -> None:
            for h in held:  # the writer hangs: no renewals
                await net(a).locks.stop_renewing(h)
            stalled.set()
            await resume.wait()
            await real_push(held, *args)

        monkeypatch.setattr(replicator, "push", stalling_push)
        tx = a.begin()
        tx.update(TABLE, item, Counter(name="c", value=100))
        commit = asyncio.create_task(tx.commit("stalled"))
        async with asyncio.timeout(5):
            await stalled.wait()
            assert await increment(b, [(TABLE, item)]) == 0  # after a's lease ran out
        resume.set()
        with pytest.raises(LockTimeout, match="lease"):
            await commit
        for peer in (a, b):
            assert await value(peer, item) == 1
            assert [c.message for c in peer.log()] == ["increment", "create c"]


class TestReadersWait:
    async def test_a_read_waits_while_a_remote_writer_holds_the_chunk(
        self, swarm: MakeSwarm, monkeypatch: pytest.MonkeyPatch
    ) -> None:
        a, b = await swarm(2)
        chunk, item = await counter_chunk(a, 3)
        await b.participate(chunk)
        locks = net(b).locks
        waiting = asyncio.Event()
        real_wait = locks.wait_readable

        async def spy(chunk_id: ChunkId) -> None:
            waiting.set()
            await real_wait(chunk_id)

        monkeypatch.setattr(locks, "wait_readable", spy)
        held = await net(a).locks.acquire(chunk, a.holders(chunk))
        reader = asyncio.create_task(value(b, item))
        async with asyncio.timeout(5):
            await waiting.wait()
        # Had the chunk been readable, the read would have finished in the same
        # step that set `waiting`; it is parked until the writer lets go.
        assert not reader.done()
        await net(a).locks.release(held)
        async with asyncio.timeout(5):
            assert await reader == 3

    async def test_a_reader_sees_a_multi_chunk_commit_whole_or_not_at_all(
        self, swarm: MakeSwarm
    ) -> None:
        """Readers on a third peer run while a writer commits to two chunks:
        every snapshot shows both counters equal."""
        w, r, s = await swarm(3)
        one_chunk, one = await counter_chunk(w, name="one")
        two_chunk, two = await counter_chunk(w, name="two")
        for chunk in (one_chunk, two_chunk):
            await r.participate(chunk)
            await s.participate(chunk)
        done = asyncio.Event()
        seen: list[tuple[int, int]] = []

        async def write() -> None:
            for _ in range(15):
                await increment(w, [(TABLE, one), (TABLE, two)])
            done.set()

        async def read(peer: Peer) -> None:
            while not done.is_set():
                tx = peer.begin()
                first = await tx.get(TABLE, one)
                second = await tx.get(TABLE, two)
                assert first is not None
                assert second is not None
                seen.append((first.value, second.value))
                await asyncio.sleep(0)  # sync-ok: a yield (0 s), so the writer task runs

        async with asyncio.timeout(20):
            await asyncio.gather(write(), read(r), read(s))
        assert seen
        assert all(x == y for x, y in seen), [p for p in seen if p[0] != p[1]]
        assert await value(r, one) == await value(s, two) == 15
