"""A chunk with its history reaches a new holder whole (the group's snapshot and log
tail), reported to a progress callback; commits replicate over slow links."""

from __future__ import annotations

from collections.abc import Awaitable, Callable

from mapapi import Peer
from mapapi.app import operations
from mapapi.net import LinkShape, Shaper

from .conftest import TABLE, Counter, MakeSwarm, counter_chunk, increment, net, value

MakePeer = Callable[..., Awaitable[Peer]]


class TestChunkArrives:
    async def test_progress_is_reported_and_everything_arrives(self, swarm: MakeSwarm) -> None:
        a, b = await swarm(2)
        chunk, _ = await counter_chunk(a)
        tx = a.begin()
        for i in range(9):
            tx.insert(TABLE, Counter(name=f"c{i}", value=i), chunk)
        await tx.commit("ten items")
        seen: list[tuple[int, int]] = []
        await b.participate(chunk, lambda done, parts: seen.append((done, parts)))
        assert seen == [(1, 1)]
        assert len(await b.begin().items(TABLE, chunk)) == 10

    async def test_progress_op_reports_nothing_when_idle(self, swarm: MakeSwarm) -> None:
        a, b = await swarm(2)
        chunk, _ = await counter_chunk(a)
        ops = operations(b)
        assert (await ops.call("participate", {"chunk": chunk}))["items"] == 1
        idle = await ops.call("participate_progress", {"chunk": chunk})
        assert (idle["received"], idle["parts"]) == (0, 0)


class TestShapedLinks:
    async def test_commits_replicate_over_slow_links(self, make_peer: MakePeer) -> None:
        a, b = await make_peer(), await make_peer()
        slow = LinkShape(latency=0.005, bandwidth=1_000_000)
        await a.start(shaper=Shaper(slow))
        await b.start(shaper=Shaper(slow))
        await b.join(a.address)
        chunk, item = await counter_chunk(a)
        await b.participate(chunk)
        await increment(b, [(TABLE, item)])
        assert await value(a, item) == 1
        sent = net(b).rpc.transport.stats.sent_by_type()
        # to a, the leader: b's commit, after the floor its read may have closed the log with
        assert sent["raft_propose"].messages in (1, 2)
        assert sent["raft_batch"].messages > 0  # b takes part in the chunk's group
