"""Crashed peers in one process (issue 7 §1-3): leases, in-doubt commits, eviction
of dead holders under the quorum rule, and restart recovery.

A crash is `Swarm.close()` without leaving: the peer's sockets close with no Bye,
no hand-over and no unlock, as after `kill -9`; a restart is a new `Peer` on the
same repository. The same scenarios with real `kill -9` of peer processes are in
tests/multiproc/test_crash_recovery.py.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator, Awaitable, Callable

import pytest

from mapapi.core.errors import CommitUncertain, MapError, PeerUnavailable, RequestTimeout
from mapapi.core.history import CommitRecord
from mapapi.core.ids import ChunkId, ItemId
from mapapi.lookup.dht.ring import chunk_key
from mapapi.net.messages import CommitApply
from mapapi.net.rpc import Request
from mapapi.service.peer import Peer
from mapapi.service.repo import Repository
from mapapi.swarm import faults
from mapapi.swarm.liveness import LivenessOptions
from mapapi.swarm.replication import encode_holder
from mapapi.testing import until

from .conftest import TABLE, Counter, counter_chunk, net, share, value

FAST = LivenessOptions(interval=0.1, suspect_after=0.4, dead_after=0.8)
LEASE = 1.0
RECOVERY = LEASE + FAST.dead_after + 5.0  # ceiling for the swarm to commit again

Start = Callable[..., Awaitable[Peer]]


@pytest.fixture
async def start(make_repo: Callable[..., Repository]) -> AsyncIterator[Start]:
    """Factory: a started peer on `repo` (joined through `seed`), closed after the test."""
    started: list[Peer] = []

    async def _start(repo: Repository, seed: str | None = None) -> Peer:
        peer = Peer.of(repo)
        started.append(peer)
        await peer.start(lease=LEASE, liveness=FAST)
        if seed is not None:
            await peer.join(seed)
        return peer

    yield _start
    for peer in started:
        await peer.close()


async def holders_of(
    start: Start, make_repo: Callable[..., Repository], n: int
) -> tuple[list[Peer], list[Repository], ChunkId, ItemId]:
    """n peers (sorted by id: the first is the arbiter) holding one counter at 0."""
    repos = [make_repo() for _ in range(n)]
    peers = [await start(repos[0])]
    for repo in repos[1:]:
        peers.append(await start(repo, peers[0].address))
    chunk, item = await counter_chunk(peers[0])
    await share(chunk, peers[1:])
    order = sorted(range(n), key=lambda i: peers[i].id)
    return [peers[i] for i in order], [repos[i] for i in order], chunk, item


async def crash(peer: Peer) -> None:
    """Close the peer's network side with no goodbye (its store stays as it is)."""
    swarm = net(peer)
    peer.swarm = None
    await swarm.close()


async def add_one(peer: Peer, item: ItemId) -> CommitRecord:
    """One commit adding 1 to the counter (no retry)."""
    tx = peer.begin()
    current = await tx.get(TABLE, item)
    assert current is not None
    tx.update(TABLE, item, Counter(name=current.name, value=current.value + 1))
    record = await tx.commit("add one")
    assert record is not None
    return record


async def add_one_retrying(peer: Peer, item: ItemId, within: float = RECOVERY) -> float:
    """`add_one`, retried on retriable errors until it commits; returns the seconds it took."""
    began = time.monotonic()
    while True:
        try:
            await add_one(peer, item)
            return time.monotonic() - began
        except MapError as exc:
            if not exc.retriable or time.monotonic() - began > within:
                raise
            await asyncio.sleep(0.05)  # sync-ok: a client's retry backoff, not a wait for state


async def settled_log(peer: Peer, chunk: ChunkId) -> list[str]:
    """The chunk's commit ids at `peer`, once no writer holds the chunk there."""
    await net(peer).locks.wait_readable(chunk)
    return [str(c.id) for c in peer.store.chunk_commits(chunk)]


async def assert_identical(peers: list[Peer], chunk: ChunkId, item: ItemId, expected: int) -> None:
    """Every peer has the same history of `chunk` and reads `expected`."""
    logs = [await settled_log(p, chunk) for p in peers]
    assert all(log == logs[0] for log in logs), logs
    assert [await value(p, item) for p in peers] == [expected] * len(peers)
    assert all(not net(p).replicator.staged(chunk) for p in peers)


def pause_at(point: str) -> asyncio.Event:
    """Arm `point` to pause the (one) commit that reaches it; the event tells when."""
    reached = asyncio.Event()

    async def pause() -> None:
        faults.disarm(point)
        reached.set()
        await asyncio.Event().wait()

    faults.arm(point, pause)
    return reached


@pytest.fixture(autouse=True)
def _disarm() -> None:
    faults.disarm()


class TestEviction:
    async def test_a_crashed_holder_is_evicted_and_the_others_commit(
        self, start: Start, make_repo: Callable[..., Repository]
    ) -> None:
        peers, _, chunk, item = await holders_of(start, make_repo, 3)
        dead, survivors = peers[1], [peers[0], peers[2]]
        await crash(dead)
        await add_one_retrying(survivors[1], item)
        for peer in survivors:
            assert dead.id not in peer.holders(chunk)
        await assert_identical(survivors, chunk, item, 1)

    async def test_the_arbiter_crashing_is_evicted_too(
        self, start: Start, make_repo: Callable[..., Repository]
    ) -> None:
        peers, _, chunk, item = await holders_of(start, make_repo, 3)
        await crash(peers[0])
        await add_one_retrying(peers[2], item)
        assert peers[1].holders(chunk) == peers[2].holders(chunk) == [peers[1].id, peers[2].id]
        await assert_identical(peers[1:], chunk, item, 1)

    async def test_without_a_quorum_nobody_evicts_and_commits_wait(
        self, start: Start, make_repo: Callable[..., Repository]
    ) -> None:
        (arbiter, other), repos, chunk, item = await holders_of(start, make_repo, 2)
        await crash(arbiter)
        await until(lambda: net(other).liveness.is_dead(arbiter.id))
        net(other).liveness.tick()  # a round with the verdict in: still no eviction
        with pytest.raises(PeerUnavailable, match="does not answer"):
            await add_one(other, item)
        assert other.holders(chunk) == sorted([arbiter.id, other.id])
        assert net(other).recovery.evictions == 0
        back = await start(repos[0], other.address)  # the arbiter restarts and rejoins
        await add_one_retrying(other, item)
        await assert_identical([back, other], chunk, item, 1)

    async def test_the_arbiter_alone_is_a_quorum_of_two(
        self, start: Start, make_repo: Callable[..., Repository]
    ) -> None:
        (arbiter, other), _, chunk, item = await holders_of(start, make_repo, 2)
        await crash(other)
        await add_one_retrying(arbiter, item)
        assert arbiter.holders(chunk) == [arbiter.id]
        assert await value(arbiter, item) == 1


class TestWriterCrash:
    async def test_a_writer_crashing_with_its_batches_staged_leaves_no_trace(
        self, start: Start, make_repo: Callable[..., Repository]
    ) -> None:
        peers, _, chunk, item = await holders_of(start, make_repo, 3)
        writer, survivors = peers[1], [peers[0], peers[2]]
        staged = pause_at("commit.staged")
        commit = asyncio.create_task(add_one(writer, item))
        await staged.wait()
        await crash(writer)  # kill -9 while it holds every lock, the batches staged
        commit.cancel()
        await asyncio.gather(commit, return_exceptions=True)
        assert all(net(p).replicator.staged(chunk) for p in survivors)  # in doubt
        took = await add_one_retrying(survivors[1], item)
        assert took < RECOVERY
        await assert_identical(survivors, chunk, item, 1)  # the writer's commit is gone

    async def test_a_commit_applied_at_one_survivor_is_applied_at_all(
        self, start: Start, make_repo: Callable[..., Repository], monkeypatch: pytest.MonkeyPatch
    ) -> None:
        peers, _, chunk, item = await holders_of(start, make_repo, 3)
        writer, (first, late) = peers[1], (peers[0], peers[2])
        arrived = asyncio.Event()

        async def swallow(req: Request) -> None:  # `late` never gets to apply it
            arrived.set()
            await asyncio.Event().wait()

        monkeypatch.setitem(net(late).rpc._handlers, CommitApply, swallow)
        commit = asyncio.create_task(add_one(writer, item))
        await arrived.wait()
        await until(lambda: len(first.store.chunk_commits(chunk)) == 2, timeout=RECOVERY)
        await crash(writer)
        commit.cancel()
        await asyncio.gather(commit, return_exceptions=True)
        await add_one_retrying(late, item)
        await assert_identical([first, late], chunk, item, 2)

    async def test_a_restarted_writer_loses_the_commit_only_it_applied(
        self, start: Start, make_repo: Callable[..., Repository]
    ) -> None:
        peers, repos, chunk, item = await holders_of(start, make_repo, 3)
        writer, survivors = peers[2], peers[:2]
        applied = pause_at("commit.applied")
        commit = asyncio.create_task(add_one(writer, item))
        await applied.wait()
        undecided = writer.store.chunk_commits(chunk)[-1].id
        await crash(writer)
        commit.cancel()
        await asyncio.gather(commit, return_exceptions=True)
        await add_one_retrying(survivors[0], item)
        back = await start(repos[2], survivors[0].address)
        assert undecided not in {c.id for c in back.store.chunk_commits(chunk)}
        assert back.store.commit_record(undecided) is None
        await assert_identical([*survivors, back], chunk, item, 1)


class TestInDoubt:
    async def test_a_holder_that_missed_the_apply_asks_the_writer(
        self, start: Start, make_repo: Callable[..., Repository], monkeypatch: pytest.MonkeyPatch
    ) -> None:
        peers, _, chunk, item = await holders_of(start, make_repo, 3)
        writer, late = peers[0], peers[2]

        def lose(req: Request) -> None:
            raise RequestTimeout("the apply message was lost")

        monkeypatch.setitem(net(late).rpc._handlers, CommitApply, lose)
        record = await add_one(writer, item)  # writer + peers[1]: a quorum confirmed
        assert not net(late).replicator.applied_here(chunk, record.id)
        await until(lambda: net(late).replicator.applied_here(chunk, record.id), RECOVERY)
        await assert_identical(peers, chunk, item, 1)

    async def test_too_few_confirmations_make_the_commit_uncertain(
        self, start: Start, make_repo: Callable[..., Repository], monkeypatch: pytest.MonkeyPatch
    ) -> None:
        peers, _, chunk, item = await holders_of(start, make_repo, 3)
        writer, others = peers[1], [peers[0], peers[2]]

        def lose(req: Request) -> None:
            raise RequestTimeout("the apply message was lost")

        for peer in others:
            monkeypatch.setitem(net(peer).rpc._handlers, CommitApply, lose)
        with pytest.raises(CommitUncertain, match="only 1 of the 3 holders"):
            await add_one(writer, item)
        # The writer answers: the others learn that it applied, and apply it too.
        for peer in others:
            await until(lambda p=peer: len(p.store.chunk_commits(chunk)) == 2, RECOVERY)
        await assert_identical(peers, chunk, item, 1)


class TestRestart:
    async def test_a_crashed_holder_restarts_catches_up_and_holds_again(
        self, start: Start, make_repo: Callable[..., Repository]
    ) -> None:
        peers, repos, chunk, item = await holders_of(start, make_repo, 3)
        for _ in range(2):
            await add_one(peers[2], item)
        await crash(peers[2])
        for _ in range(3):
            await add_one_retrying(peers[0], item)
        back = await start(repos[2], peers[0].address)
        everyone = [peers[0], peers[1], back]
        await until(lambda: all(back.id in p.holders(chunk) for p in everyone))
        await add_one_retrying(back, item)
        await assert_identical(everyone, chunk, item, 6)

    async def test_a_holder_that_restarted_is_asked_where_it_serves_now(
        self, start: Start, make_repo: Callable[..., Repository]
    ) -> None:
        repos = [make_repo(), make_repo()]
        first = await start(repos[0])
        chunk, item = await counter_chunk(first)
        await add_one(first, item)
        newcomer = await start(repos[1], first.address)
        before = first.address
        key, stale = chunk_key(chunk), encode_holder(net(first).members.me)
        ring = net(newcomer).chord
        await until(lambda: stale in ring.storage.get(key, ring.clock()))  # a replica
        await crash(first)
        back = await start(repos[0], newcomer.address)  # a new port, told to newcomer
        assert back.address != before
        # Leave the index naming only the address of before the restart, as it
        # does until that entry expires (30 s) whenever it sorts after the new one.
        await net(back).replicator.unregister(chunk)
        indexed = await net(newcomer).replicator._find_in_index(chunk)
        assert indexed is not None
        assert [(m.id, m.address) for m in indexed.holders] == [(back.id, before)]
        await newcomer.participate(chunk)
        assert await value(newcomer, item) == 1
        assert sorted(newcomer.holders(chunk)) == sorted([back.id, newcomer.id])
