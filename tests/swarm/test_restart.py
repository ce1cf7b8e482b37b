"""A peer that stops gracefully stays a member of its chunks' groups (the others
commit while a majority of each group's voters is up); restarted, it catches up."""

from __future__ import annotations

import pytest

from mapapi import Peer
from mapapi.core.errors import PeerNotRunning
from mapapi.store import SqliteStore

from .conftest import TABLE, MakeSwarm, counter_chunk, increment, log_ids, share, value


class TestGracefulStop:
    async def test_others_commit_after_a_holder_stops_and_it_catches_up(
        self, swarm: MakeSwarm
    ) -> None:
        a, b = await swarm(2)
        chunk, item = await counter_chunk(a)
        await share(chunk, [b])
        await increment(b, [(TABLE, item)])
        assert isinstance(b.store, SqliteStore)
        path, b_id = b.store.path, b.id
        await b.close()
        assert set(a.holders(chunk)) == {a.id, b_id}  # b stays a member (a learner)
        await increment(a, [(TABLE, item)])  # a, the one voter, commits alone

        again = Peer(SqliteStore(path), b_id)
        try:
            await again.start("tcp://127.0.0.1:0")
            await again.join(a.address)
            assert await again.rejoin() == [chunk]
            assert set(a.holders(chunk)) == {a.id, b_id}
            assert await value(again, item) == 2
            await increment(again, [(TABLE, item)])
            assert await value(a, item) == 3
            assert await log_ids(again) == await log_ids(a)
        finally:
            await again.close()


class TestStaleHolders:
    async def test_a_peer_alone_refuses_to_commit_to_a_shared_chunk(self, swarm: MakeSwarm) -> None:
        a, b = await swarm(2)
        chunk, item = await counter_chunk(a)
        await share(chunk, [b])
        assert isinstance(b.store, SqliteStore)
        path, b_id = b.store.path, b.id
        await b.close()
        alone = Peer(SqliteStore(path), b_id)  # no swarm: its commits would reach nobody
        try:
            tx = alone.begin()
            current = await tx.get(TABLE, item)
            assert current is not None
            tx.update(TABLE, item, type(current)(name="c", value=99))
            with pytest.raises(PeerNotRunning, match="shared with other peers"):
                await tx.commit("offline edit")
        finally:
            await alone.close()
        assert await value(a, item) == 0
