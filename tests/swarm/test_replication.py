"""Chunks across peers: participation with history, commits reaching every holder."""

from __future__ import annotations

from collections.abc import Awaitable, Callable

import pytest

from mapapi import ChunkId, ConflictError, ItemId, Peer
from mapapi.net import Ping
from mapapi.table import message_class

Counter = message_class("mapapi.v1.Counter")
Swarm = Callable[..., Awaitable[list[Peer]]]


async def _counter_chunk(peer: Peer, value: int = 0) -> tuple[ChunkId, ItemId]:
    await peer.create_table("counters", "mapapi.v1.Counter")
    chunk = await peer.create_chunk("counters")
    tx = peer.begin()
    item = tx.insert("counters", Counter(name="c", value=value), chunk)
    await tx.commit("start")
    return chunk, item


async def _value(peer: Peer, item: ItemId, at: int | None = None) -> int:
    message = await peer.begin(at).get("counters", item)
    assert message is not None
    return int(message.value)


class TestMembership:
    async def test_every_peer_learns_the_whole_swarm_from_one_member(self, swarm: Swarm) -> None:
        peers = await swarm(4)
        for peer in peers:
            others = {s.member.id for s in peer.members()}
            assert others == {p.id for p in peers} - {peer.id}


class TestParticipation:
    async def test_newcomer_gets_items_and_history(self, swarm: Swarm) -> None:
        a, b = await swarm(2)
        chunk, item = await _counter_chunk(a, 42)
        old = a.now()
        tx = a.begin()
        tx.update("counters", item, Counter(name="c", value=21))
        await tx.commit("halve")
        assert await b.participate(chunk) == "counters"
        assert await _value(b, item) == 21
        assert await _value(b, item, at=old) == 42
        assert set(a.holders(chunk)) == set(b.holders(chunk)) == {a.id, b.id}

    async def test_reading_an_unknown_item_fetches_its_chunk(self, swarm: Swarm) -> None:
        a, b = await swarm(2)
        chunk, item = await _counter_chunk(a, 7)
        await b.create_table("counters", "mapapi.v1.Counter")  # the schema, not the data
        assert b.swarm is not None
        await b.swarm.rpc.request(a.address, Ping())  # b hears from a: clocks merge
        assert await _value(b, item) == 7
        assert chunk in {c.id for c in b.chunks()}
        assert chunk in {c.id for c in b.chunks()}


class TestCommitAcrossHolders:
    async def test_commits_reach_every_holder(self, swarm: Swarm) -> None:
        peers = await swarm(3)
        chunk, item = await _counter_chunk(peers[0])
        for peer in peers[1:]:
            await peer.participate(chunk)
        for round_ in range(3):
            for peer in peers:
                tx = peer.begin()
                current = await tx.get("counters", item)
                assert current is not None
                tx.update("counters", item, Counter(name="c", value=current.value + 1))
                await tx.commit(f"round {round_}")
        for peer in peers:
            assert await _value(peer, item) == 9
            assert [c.id for c in peer.log()] == [c.id for c in peers[0].log()]

    async def test_conflicts_are_detected_as_on_one_peer(self, swarm: Swarm) -> None:
        a, b = await swarm(2)
        chunk, item = await _counter_chunk(a)
        await b.participate(chunk)
        ta, tb = a.begin(), b.begin()
        ta.update("counters", item, Counter(name="c", value=1))
        tb.update("counters", item, Counter(name="c", value=2))
        await ta.commit("a")
        with pytest.raises(ConflictError) as caught:
            await tb.commit("b")
        assert [c.item_id for c in caught.value.conflicts] == [item]
        theirs = caught.value.conflicts[0].theirs
        assert theirs.data == Counter(name="c", value=1).SerializeToString()
        assert await _value(b, item) == 1
