"""A ConflictError that crosses the wire keeps its conflicts (issue 16).

The server side loses a real commit race on a real peer and answers the
request with the ConflictError; the client raises it again with the same
conflicts, while `merge()` says where the transaction lives.
"""

from __future__ import annotations

import pytest

from mapapi import ConflictError, Peer
from mapapi.core.change import Op
from mapapi.core.errors import UsageError
from mapapi.core.table import message_class
from mapapi.net import Ping, Request

from .conftest import MakeRpc

Counter = message_class("mapapi.v1.Counter")


async def _lost_race(peer: Peer) -> ConflictError:
    """Two transactions update one item; the second loses (and one insert does not conflict)."""
    await peer.create_table("c", Counter)
    chunk = await peer.create_chunk("c")
    seed = peer.begin()
    item = seed.insert("c", Counter(name="x", value=0), chunk)
    await seed.commit("seed")
    first, second = peer.begin(), peer.begin()
    first.update("c", item, Counter(name="x", value=1))
    second.update("c", item, Counter(name="x", value=2))
    second.insert("c", Counter(name="y", value=5), chunk)
    await first.commit("first")
    with pytest.raises(ConflictError) as caught:
        await second.commit("second")
    return caught.value


async def _across(make_rpc: MakeRpc, sent: ConflictError) -> ConflictError:
    """`sent` as a client raises it, a server on 127.0.0.1 having answered a request with it."""
    client, server = await make_rpc(), await make_rpc()

    def refuse(req: Request) -> None:
        raise sent

    server.register(Ping, refuse)
    with pytest.raises(ConflictError) as caught:
        await client.request(server.address, Ping())
    return caught.value


class TestRemoteConflict:
    async def test_conflicts_survive_an_rpc(self, make_rpc: MakeRpc, memory_peer: Peer) -> None:
        sent = await _lost_race(memory_peer)
        got = await _across(make_rpc, sent)

        assert str(got) == str(sent)
        assert got.seen_at == sent.seen_at > 0
        assert got.conflicts == sent.conflicts
        (conflict,) = got.conflicts
        assert (conflict.table, conflict.chunk_id) == ("c", sent.conflicts[0].chunk_id)
        assert conflict.base is not None
        assert Counter.FromString(conflict.base.data).value == 0
        assert conflict.ours is not None
        assert conflict.ours.op is Op.UPDATE
        assert Counter.FromString(conflict.ours.data).value == 2
        assert Counter.FromString(conflict.theirs.data).value == 1

    async def test_a_remote_conflict_is_merged_where_its_transaction_lives(
        self, make_rpc: MakeRpc, memory_peer: Peer
    ) -> None:
        sent = await _lost_race(memory_peer)
        got = await _across(make_rpc, sent)

        with pytest.raises(UsageError, match="merge it where it was committed"):
            got.merge()
        assert sent.merge().changes  # the sender's own error still merges: the insert

    async def test_a_view_hint_travels_as_sent(self, make_rpc: MakeRpc) -> None:
        sent = ConflictError([], None, 3)
        sent.name_view("mapctl --view bob")

        got = await _across(make_rpc, sent)

        assert str(got) == str(sent)
        assert "`mapctl --view bob diff`" in str(got)
        assert got.retriable
        assert got.exit_code == 3
