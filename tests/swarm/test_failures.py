"""Crashed peers in one process, with every commit through the chunks' Raft logs
(DESIGN §13, issue 13): a dead leader is replaced and commits resume; a minority of
voters cannot commit and says which voters are missing; a dead member is removed by
the leader after a while and a learner takes its vote; a peer that restarts catches
up; and the issue's minimal race ends with one history and at most one winner.

A crash is `Swarm.close()` without leaving: the peer's sockets close with no Bye
and no hand-over, as after `kill -9`; a restart is a new `Peer` on the same
repository. The same scenarios with real peer processes are in tests/multiproc/.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator, Awaitable, Callable

import pytest

from mapapi.core.errors import ConflictError, MapError, NoQuorum
from mapapi.core.history import CommitRecord
from mapapi.core.ids import ChunkId, ItemId
from mapapi.lookup.dht.ring import chunk_key
from mapapi.service.peer import Peer
from mapapi.service.repo import Repository
from mapapi.service.stale import staleness
from mapapi.swarm.liveness import LivenessOptions
from mapapi.swarm.raft_wire import node_id
from mapapi.swarm.replication import encode_holder
from mapapi.testing import until

from .conftest import TABLE, Counter, counter_chunk, log_ids, net, share, value

FAST = LivenessOptions(interval=0.1, suspect_after=0.4, dead_after=0.8, remove_after=0.5)
RECOVERY = 10.0  # ceiling for the swarm to commit again (elections take about a second)

Start = Callable[..., Awaitable[Peer]]


@pytest.fixture
async def start(make_repo: Callable[..., Repository]) -> AsyncIterator[Start]:
    """Factory: a started peer on `repo` (joined through `seed`), closed after the test."""
    started: list[Peer] = []

    async def _start(repo: Repository, seed: str | None = None) -> Peer:
        peer = Peer.of(repo)
        started.append(peer)
        await peer.start(liveness=FAST)
        if seed is not None:
            await peer.join(seed)
        return peer

    yield _start
    for peer in started:
        await peer.close()


async def holders_of(
    start: Start, make_repo: Callable[..., Repository], n: int
) -> tuple[list[Peer], list[Repository], ChunkId, ItemId]:
    """n peers holding one counter at 0 (with 3 or 4 of them, 3 vote)."""
    repos = [make_repo() for _ in range(n)]
    peers = [await start(repos[0])]
    for repo in repos[1:]:
        peers.append(await start(repo, peers[0].address))
    chunk, item = await counter_chunk(peers[0])
    await share(chunk, peers[1:])
    # a learner lagging when it joined is promoted by a later round of the leader's
    voters = 3 if n >= 3 else 1
    await until(
        lambda: all(len(net(p).groups.config(chunk).voters) == voters for p in peers),
        timeout=RECOVERY,
    )
    return peers, repos, chunk, item


async def leader_among(peers: list[Peer], chunk: ChunkId) -> Peer:
    """The peer that leads `chunk`, once every one of `peers` names it."""

    def agreed() -> bool:
        leaders = {net(p).groups.leader(chunk) for p in peers}
        return len(leaders) == 1 and None not in leaders and leaders <= {p.id for p in peers}

    await until(agreed, timeout=RECOVERY)
    leader = net(peers[0]).groups.leader(chunk)
    return next(p for p in peers if p.id == leader)


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


async def assert_one_history(peers: list[Peer], item: ItemId, expected: int) -> None:
    """Every peer, caught up with the leader, has the same commits and reads `expected`."""
    logs = [await log_ids(p) for p in peers]
    assert all(log == logs[0] for log in logs), logs
    histories = {tuple(str(r.commit_id) for r in p.history(item)) for p in peers}
    assert len(histories) == 1, histories
    assert [await value(p, item) for p in peers] == [expected] * len(peers)


class TestLeader:
    async def test_a_dead_leader_is_replaced_and_commits_resume(
        self, start: Start, make_repo: Callable[..., Repository]
    ) -> None:
        peers, _, chunk, item = await holders_of(start, make_repo, 3)
        leader = await leader_among(peers, chunk)
        await add_one(leader, item)
        survivors = [p for p in peers if p is not leader]
        await crash(leader)
        took = await add_one_retrying(survivors[0], item)
        assert took < RECOVERY
        assert (await leader_among(survivors, chunk)) is not leader
        await add_one(survivors[1], item)
        await assert_one_history(survivors, item, 3)


class TestMinority:
    @pytest.mark.parametrize("survivor_leads", [True, False])
    async def test_a_minority_cannot_commit_and_names_the_missing_voters(
        self, start: Start, make_repo: Callable[..., Repository], survivor_leads: bool
    ) -> None:
        peers, _, chunk, item = await holders_of(start, make_repo, 3)
        await add_one(peers[0], item)
        leader = await leader_among(peers, chunk)
        survivor = leader if survivor_leads else next(p for p in peers if p is not leader)
        gone = [p for p in peers if p is not survivor]
        view = survivor.begin()
        current = await view.get(TABLE, item)
        assert current is not None
        for peer in gone:
            await crash(peer)
        await until(lambda: not any(net(survivor).liveness.answers(p.id) for p in gone))
        view.update(TABLE, item, Counter(name=current.name, value=99))
        with pytest.raises(NoQuorum) as caught:
            await view.commit("alone")
        assert f"chunk {chunk.short}" in str(caught.value)
        assert "1 of 3 voters reachable" in str(caught.value)
        for peer in gone:
            assert peer.id.short in str(caught.value)
        assert caught.value.retriable
        assert [r.data for r in survivor.history(item)][-1] == current.SerializeToString()


class TestMembers:
    async def test_a_dead_member_is_removed_by_the_leader_and_a_learner_votes(
        self, start: Start, make_repo: Callable[..., Repository]
    ) -> None:
        peers, _, chunk, item = await holders_of(start, make_repo, 4)  # 3 voters, 1 learner
        leader = await leader_among(peers, chunk)
        config = net(leader).groups.config(chunk)
        (learner,) = [p for p in peers if node_id(p.id) in config.learners]
        roles = leader.roles(chunk)  # what `chunk list` shows
        assert roles[leader.id] == "leader"
        assert roles[learner.id] == "learner"
        assert sorted(roles.values()) == ["leader", "learner", "voter", "voter"]
        dead = next(p for p in peers if p not in (leader, learner))
        await crash(dead)
        living = [p for p in peers if p is not dead]
        # after FAST.remove_after of being declared dead, through the chunk's log
        await until(lambda: all(dead.id not in p.holders(chunk) for p in living), RECOVERY)
        voting = {node_id(p.id) for p in living}  # the learner takes the vote, a change later
        await until(lambda: net(leader).groups.config(chunk).voters == voting, RECOVERY)
        await add_one(learner, item)
        await assert_one_history(living, item, 1)

    async def test_a_member_that_left_and_stays_away_loses_its_place(
        self, start: Start, make_repo: Callable[..., Repository]
    ) -> None:
        peers, _, chunk, item = await holders_of(start, make_repo, 4)  # 3 voters, 1 learner
        leader = await leader_among(peers, chunk)
        (learner,) = [
            p for p in peers if node_id(p.id) in net(leader).groups.config(chunk).learners
        ]
        left = next(p for p in peers if p not in (leader, learner))
        await left.close()  # a goodbye keeps it a member, until silent long enough
        living = [p for p in peers if p is not left]
        assert left.id in leader.holders(chunk)

        await until(lambda: all(left.id not in p.holders(chunk) for p in living), RECOVERY)
        voting = {node_id(p.id) for p in living}  # the learner takes its vote
        await until(lambda: net(leader).groups.config(chunk).voters == voting, RECOVERY)
        await add_one(learner, item)
        await assert_one_history(living, item, 1)


class TestRestart:
    async def test_a_restarted_peer_rejoins_its_groups_and_catches_up(
        self, start: Start, make_repo: Callable[..., Repository]
    ) -> None:
        peers, repos, chunk, item = await holders_of(start, make_repo, 3)
        await add_one(peers[2], item)
        await crash(peers[2])
        for _ in range(3):
            await add_one_retrying(peers[0], item)
        back = await start(repos[2], peers[0].address)
        everyone = [peers[0], peers[1], back]
        assert all(set(p.holders(chunk)) == {q.id for q in everyone} for p in everyone)
        assert await value(back, item) == 4  # caught up
        await add_one_retrying(back, item)
        await assert_one_history(everyone, item, 5)

    async def test_a_member_removed_while_away_joins_again_and_catches_up(
        self, start: Start, make_repo: Callable[..., Repository]
    ) -> None:
        peers, repos, chunk, item = await holders_of(start, make_repo, 3)
        await add_one(peers[2], item)
        away = peers[2]
        await crash(away)
        living = peers[:2]
        # the leader removes it after FAST.remove_after of being dead, through the log
        await until(lambda: all(away.id not in p.holders(chunk) for p in living), RECOVERY)
        await add_one_retrying(peers[0], item)
        back = await start(repos[2], peers[0].address)  # its group still counts it in

        # it knows no leader (the others drop its messages), asks, is taken in again
        everyone = [*living, back]
        await until(lambda: all(back.id in p.holders(chunk) for p in everyone), RECOVERY)
        await until(lambda: net(back).groups.leader(chunk) is not None, RECOVERY)
        assert await value(back, item) == 2  # its state was reinstalled
        await add_one_retrying(back, item)
        await assert_one_history(everyone, item, 3)

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


class TestRace:
    async def test_two_views_racing_on_one_item_leave_one_history(
        self, start: Start, make_repo: Callable[..., Repository]
    ) -> None:
        """The issue's minimal race, ten times: two views on two peers, begun at the
        same version, write one item; at most one commit is acknowledged, and every
        holder ends with the same history."""
        peers, _, _, item = await holders_of(start, make_repo, 3)
        a, b = peers[1], peers[2]  # neither founded the chunk
        acknowledged = 0
        for round_ in range(10):
            views = [a.begin(), b.begin()]
            seen = [await v.get(TABLE, item) for v in views]
            assert seen[0] == seen[1], f"round {round_}: the views began at different versions"
            assert seen[0] is not None
            for view, value_ in zip(views, (2 * round_ + 1, 2 * round_ + 2), strict=True):
                view.update(TABLE, item, Counter(name=seen[0].name, value=value_))
            results = await asyncio.gather(
                *(v.commit(f"round {round_}") for v in views), return_exceptions=True
            )
            won = [r for r in results if isinstance(r, CommitRecord)]
            lost = [r for r in results if not isinstance(r, CommitRecord)]
            assert len(won) <= 1, f"round {round_}: both commits were acknowledged"
            assert all(isinstance(e, ConflictError) for e in lost), lost
            acknowledged += len(won)
        assert acknowledged >= 1
        await assert_one_history(peers, item, await value(a, item))
        assert len(a.history(item)) == 1 + acknowledged  # the insert, then each winner


class TestStaleViews:
    async def test_a_stale_view_reads_its_replica_with_no_leader_and_says_how_old(
        self, start: Start, make_repo: Callable[..., Repository]
    ) -> None:
        peers, _, chunk, item = await holders_of(start, make_repo, 3)
        await add_one(peers[0], item)
        leader = await leader_among(peers, chunk)
        alone = next(p for p in peers if p is not leader)
        assert await value(alone, item) == 1  # its replica has the commit
        gone = [p for p in peers if p is not alone]
        for peer in gone:
            await crash(peer)
        await until(lambda: not any(net(alone).liveness.answers(p.id) for p in gone))

        view = alone.begin(stale=True)
        current = await view.get(TABLE, item)
        age = staleness(alone)

        assert current is not None
        assert current.value == 1
        assert view.begin_time == alone.store.clock()
        assert age.time == alone.store.clock()
        assert age.silent_s is not None
        assert age.silent_s > 0  # its leader is gone: it says how long it has been silent
        view.update(TABLE, item, Counter(name=current.name, value=2))
        with pytest.raises(NoQuorum):  # a commit still needs the chunk's voters
            await view.commit("offline")
        assert await alone.begin(stale=True).get(TABLE, item) == current  # nothing changed
