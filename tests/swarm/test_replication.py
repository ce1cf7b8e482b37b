"""Chunks across peers: participation with history, commits reaching every holder,
leaving (ChunkTest in the original: ParticipationRequest, FullJoinTwice, Leave,
RemoteInsert, RemoteUpdate, SendHistory)."""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable

import pytest

from mapapi import ConflictError, Op, Peer, UsageError
from mapapi.core.errors import RequestTimeout
from mapapi.net import Ping
from tests.swarm.conftest import (
    TABLE,
    Counter,
    MakeSwarm,
    counter_chunk,
    increment,
    log_ids,
    net,
    share,
    value,
)


class TestParticipation:
    async def test_asking_again_after_a_late_state_waits_for_it(self, swarm: MakeSwarm) -> None:
        """A join whose state does not arrive in time leaves this peer a member of the
        group; asking to participate again waits for the state instead of returning
        at once with nothing here (`query-bbox --load` asks again)."""
        a, b = await swarm(2)
        chunk, item = await counter_chunk(a, 7)
        with pytest.raises(RequestTimeout, match="did not arrive within 0 s"):
            await net(b).group_members.join(chunk, via=a.id, timeout=0)
        assert net(b).replicator.holds(chunk)  # taken in, its state on its way

        assert await b.participate(chunk) == TABLE

        assert await value(b, item) == 7

    @pytest.mark.parametrize("n", [2, 5, 8])
    async def test_replication_after_participate_and_after_commits(
        self, swarm: MakeSwarm, n: int
    ) -> None:
        peers = await swarm(n)
        owner = peers[0]
        chunk, item = await counter_chunk(owner, 100)
        await share(chunk, peers[1:])
        for peer in peers:
            assert await value(peer, item) == 100
        for index, peer in enumerate(peers):  # every holder commits once
            tx = peer.begin()
            current = await tx.get(TABLE, item)
            assert current is not None
            tx.update(TABLE, item, Counter(name="c", value=current.value + index))
            await tx.commit(f"add {index}")
        expected = 100 + sum(range(n))
        everyone = {p.id for p in peers}
        for peer in peers:
            assert await value(peer, item) == expected
            assert await log_ids(peer) == await log_ids(owner)
            assert set(peer.holders(chunk)) == everyone
            assert len(peer.history(item)) == n + 1

    async def test_history_travels_with_the_chunk(self, swarm: MakeSwarm) -> None:
        a, b = await swarm(2)
        chunk, item = await counter_chunk(a, 42)
        old = a.now()
        tx = a.begin()
        tx.update(TABLE, item, Counter(name="c", value=21))
        await tx.commit("halve")
        assert await b.participate(chunk) == TABLE
        assert await value(b, item) == 21
        assert await value(b, item, at=old) == 42  # a view at an old time, on the newcomer
        assert [r.update_time for r in b.history(item)] == [r.update_time for r in a.history(item)]
        assert set(a.holders(chunk)) == set(b.holders(chunk)) == {a.id, b.id}

    async def test_full_join_twice(
        self, swarm: MakeSwarm, make_peer: Callable[..., Awaitable[Peer]]
    ) -> None:
        root, a = await swarm(2)
        chunk, item = await counter_chunk(root, 1)
        assert root.holders(chunk) == [root.id]
        await a.participate(chunk)
        assert set(root.holders(chunk)) == {root.id, a.id}
        late = await make_peer()  # B starts only now
        await late.start()
        await late.join(root.address)
        await late.participate(chunk)
        everyone = {root.id, a.id, late.id}
        for peer in (root, a, late):
            assert set(peer.holders(chunk)) == everyone
            assert list((await peer.begin().items(TABLE, chunk)).keys()) == [item]

    async def test_participating_again_changes_nothing(self, swarm: MakeSwarm) -> None:
        a, b = await swarm(2)
        chunk, _ = await counter_chunk(a)
        await b.participate(chunk)
        await b.participate(chunk)
        await net(b).rpc.request(a.address, Ping())
        assert sorted(a.holders(chunk)) == sorted(b.holders(chunk)) == sorted([a.id, b.id])

    async def test_reading_an_unknown_item_fetches_its_chunk(self, swarm: MakeSwarm) -> None:
        a, b = await swarm(2)
        chunk, item = await counter_chunk(a, 7)
        await b.create_table(TABLE, Counter)  # the schema, not the data
        await net(b).rpc.request(a.address, Ping())  # b hears from a: clocks merge
        assert await value(b, item) == 7
        assert chunk in {c.id for c in b.chunks()}
        assert set(a.holders(chunk)) == {a.id, b.id}

    async def test_two_reads_fetch_an_unknown_chunk_once(self, swarm: MakeSwarm) -> None:
        a, b = await swarm(2)
        chunk, first = await counter_chunk(a, 1)
        tx = a.begin()
        second = tx.insert(TABLE, Counter(name="d", value=2), chunk)
        await tx.commit("second item")
        await b.create_table(TABLE, Counter)
        await net(b).rpc.request(a.address, Ping())  # b hears from a: clocks merge
        async with asyncio.timeout(10):
            assert await asyncio.gather(value(b, first), value(b, second)) == [1, 2]
        assert [c.id for c in b.chunks()] == [chunk]
        assert sorted(a.holders(chunk)) == sorted(b.holders(chunk)) == sorted([a.id, b.id])
        assert await log_ids(a) == await log_ids(b)

    async def test_newcomers_joining_through_one_holder_at_once(self, swarm: MakeSwarm) -> None:
        owner, *newcomers = await swarm(4)
        chunk, item = await counter_chunk(owner)
        async with asyncio.timeout(20):
            await asyncio.gather(*(p.participate(chunk) for p in newcomers))
        everyone = {p.id for p in (owner, *newcomers)}
        for peer in (owner, *newcomers):
            assert set(peer.holders(chunk)) == everyone, peer.name
        await increment(newcomers[0], [(TABLE, item)])
        for peer in (owner, *newcomers):
            assert await value(peer, item) == 1
            assert await log_ids(peer) == await log_ids(owner)


class TestParticipationDuringCommits:
    async def test_a_commit_that_read_the_holders_before_a_join_reaches_the_newcomer(
        self, swarm: MakeSwarm
    ) -> None:
        """The writer reads the holder set, then waits for the lock while the
        newcomer is added: its commit must still reach the newcomer."""
        owner, writer, newcomer = await swarm(3)
        chunk, item = await counter_chunk(owner)
        await writer.participate(chunk)
        tx = writer.begin()
        tx.update(TABLE, item, Counter(name="c", value=5))
        commits: list[asyncio.Task[object]] = []

        def on_part(received: int, total: int) -> None:
            # The owner holds the lock and sends the state: commit now, with the
            # holder set as it was before the join.
            if not commits:
                commits.append(asyncio.get_running_loop().create_task(tx.commit("racing")))

        async with asyncio.timeout(20):
            await net(newcomer).replicator.participate(chunk, on_part)
            await asyncio.gather(*commits)
        assert commits
        for peer in (owner, writer, newcomer):
            assert await value(peer, item) == 5, peer.name
            assert await log_ids(peer) == await log_ids(owner), peer.name
            assert set(peer.holders(chunk)) == {owner.id, writer.id, newcomer.id}

    @pytest.mark.parametrize("newcomer_rank", ["lowest", "highest"])
    async def test_no_commit_lost_while_peers_join(
        self, swarm: MakeSwarm, newcomer_rank: str
    ) -> None:
        """Two holders keep committing while two more join; the newcomers end
        with the same history. A newcomer with the lowest id becomes the new
        arbiter: writers that still knew the old one must not deadlock with it."""
        peers = sorted(await swarm(4), key=lambda p: p.id)
        if newcomer_rank == "lowest":
            newcomers, holders = peers[:2], peers[2:]
        else:
            holders, newcomers = peers[:2], peers[2:]
        chunk, item = await counter_chunk(holders[0])
        await holders[1].participate(chunk)
        rounds = 8

        async def keep_committing(peer: Peer) -> None:
            for _ in range(rounds):
                await increment(peer, [(TABLE, item)])

        async with asyncio.timeout(30):
            await asyncio.gather(
                *(keep_committing(p) for p in holders),
                *(p.participate(chunk) for p in newcomers),
            )
        everyone = {p.id for p in peers}
        for peer in peers:
            assert await value(peer, item) == 2 * rounds, peer.name
            assert await log_ids(peer) == await log_ids(holders[0]), peer.name
            assert set(peer.holders(chunk)) == everyone, peer.name


class TestLeave:
    async def test_leaving_shrinks_the_holder_sets_and_drops_the_data(
        self, swarm: MakeSwarm
    ) -> None:
        a, b, c = await swarm(3)
        chunk, item = await counter_chunk(a, 1)
        await share(chunk, [b, c])
        await c.leave_chunk(chunk)
        assert set(a.holders(chunk)) == set(b.holders(chunk)) == {a.id, b.id}
        assert chunk not in {i.id for i in c.chunks()}
        assert c.store.read(item, c.now()) is None
        await increment(b, [(TABLE, item)])  # commits no longer go to the leaver
        assert await value(a, item) == 2
        assert c.store.read(item, c.now()) is None
        assert chunk not in {i.id for i in c.chunks()}

    @pytest.mark.parametrize("leaver_rank", ["lowest", "highest"])
    async def test_leaving_while_others_commit(self, swarm: MakeSwarm, leaver_rank: str) -> None:
        """Writers that still count the leaver (the arbiter, if it has the lowest
        id) among the holders lock again without it; no commit reaches it."""
        peers = sorted(await swarm(3), key=lambda p: p.id)
        leaver = peers[0] if leaver_rank == "lowest" else peers[-1]
        writers = [p for p in peers if p is not leaver]
        chunk, item = await counter_chunk(writers[0])
        await share(chunk, [writers[1], leaver])
        rounds = 8

        async def keep_committing(peer: Peer) -> None:
            for _ in range(rounds):
                await increment(peer, [(TABLE, item)])

        async with asyncio.timeout(30):
            await asyncio.gather(*(keep_committing(p) for p in writers), leaver.leave_chunk(chunk))
        for peer in writers:
            assert await value(peer, item) == 2 * rounds
            assert set(peer.holders(chunk)) == {p.id for p in writers}
        assert await log_ids(writers[0]) == await log_ids(writers[1])
        assert leaver.chunks() == []
        assert leaver.store.chunk_revisions(chunk) == []

    async def test_the_last_holder_cannot_leave_without_force(self, swarm: MakeSwarm) -> None:
        a, b = await swarm(2)
        chunk, item = await counter_chunk(a, 1)
        await b.participate(chunk)
        await b.leave_chunk(chunk)
        assert a.holders(chunk) == [a.id]
        with pytest.raises(UsageError, match="last holder"):
            await a.leave_chunk(chunk)
        assert await value(a, item) == 1
        await a.leave_chunk(chunk, force=True)
        assert a.chunks() == []

    async def test_a_leaver_can_join_again(self, swarm: MakeSwarm) -> None:
        a, b = await swarm(2)
        chunk, item = await counter_chunk(a, 1)
        await b.participate(chunk)
        await b.leave_chunk(chunk)
        await increment(a, [(TABLE, item)])
        await b.participate(chunk)
        assert await value(b, item) == 2
        await increment(b, [(TABLE, item)])
        assert await value(a, item) == 3
        assert await log_ids(a) == await log_ids(b)


class TestCommitAcrossHolders:
    async def test_commits_reach_every_holder(self, swarm: MakeSwarm) -> None:
        peers = await swarm(3)
        chunk, item = await counter_chunk(peers[0])
        await share(chunk, peers[1:])
        for round_ in range(3):
            for peer in peers:
                await increment(peer, [(TABLE, item)], f"round {round_}")
        for peer in peers:
            assert await value(peer, item) == 9
            assert await log_ids(peer) == await log_ids(peers[0])

    async def test_remote_insert_and_remove(self, swarm: MakeSwarm) -> None:
        a, b = await swarm(2)
        chunk, first = await counter_chunk(a, 1)
        await b.participate(chunk)
        tx = b.begin()
        second = tx.insert(TABLE, Counter(name="d", value=2), chunk)
        tx.remove(TABLE, first)
        await tx.commit("insert d, remove c")
        seen = await a.begin().items(TABLE, chunk)
        assert list(seen) == [second]
        assert a.history(first)[-1].removed

    async def test_conflicts_are_detected_as_on_one_peer(self, swarm: MakeSwarm) -> None:
        a, b = await swarm(2)
        chunk, item = await counter_chunk(a)
        await b.participate(chunk)
        ta, tb = a.begin(), b.begin()
        ta.update(TABLE, item, Counter(name="c", value=1))
        tb.update(TABLE, item, Counter(name="c", value=2))
        await ta.commit("a")
        with pytest.raises(ConflictError) as caught:
            await tb.commit("b")
        [conflict] = caught.value.conflicts
        assert conflict.item_id == item
        assert conflict.base is not None
        assert conflict.base.data == Counter(name="c", value=0).SerializeToString()
        assert conflict.ours is not None
        assert conflict.ours.op is Op.UPDATE
        assert conflict.ours.data == Counter(name="c", value=2).SerializeToString()
        assert conflict.theirs.data == Counter(name="c", value=1).SerializeToString()
        assert conflict.theirs.author == a.id
        assert await value(b, item) == 1
        assert await value(a, item) == 1
        merged = caught.value.merge()  # nothing but the conflicting change: empty
        assert merged.changes == []
