"""Oversized values and absurd counts are refused, naming the limit (issue 7 §5).

Every case sends the hostile message over real zmq sockets on 127.0.0.1 to a
real endpoint (an Rpc, a Chord node, a started peer) and checks the error the
sender gets back, that the receiver kept nothing of it, and that it still
serves. The limits themselves live in `mapapi.core.limits`.
"""

from __future__ import annotations

import asyncio
import math
import os
from collections.abc import Awaitable, Callable

import pytest
import zmq
import zmq.asyncio
from google.protobuf import struct_pb2

from mapapi._pb.mapapi.v1 import lookup_pb2
from mapapi.core import limits
from mapapi.core.errors import LimitExceeded, ProtocolError, UsageError
from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId
from mapapi.lookup.dht.chord import ChordNode, key_bytes
from mapapi.lookup.spatial import BBox
from mapapi.lookup.spatial_index import encode_filter
from mapapi.net import Ping, Pong, codec
from mapapi.net.codec import Envelope, ErrorReply, Kind
from mapapi.net.messages import (
    Ack,
    ChordAdd,
    ChordEntry,
    ChordFindSuccessor,
    ChordStore,
    Hello,
    Member,
    TriggerPush,
    Welcome,
)
from mapapi.net.stats import OTHERS, Stats
from mapapi.service.peer import Peer
from mapapi.swarm.subscriptions import SubscriptionSpec, decode_subscription, region_filter

from .conftest import MakeRpc

KEY = key_bytes(12345)
REGION = BBox(0, 0, 0, 10, 10, 3)


async def _ask(sock: zmq.asyncio.Socket, env: Envelope) -> Envelope:
    await sock.send(codec.encode(env))
    async with asyncio.timeout(5):
        return codec.decode(await sock.recv())


def _revision(data: bytes) -> Revision:
    writer = PeerId.new()
    return Revision(ItemId.new(), "t", ChunkId.new(), data, 5, 5, False, writer, CommitId.new())


def _request(body: object, lamport: int = 1, request_id: int = 7) -> Envelope:
    return Envelope(request_id, PeerId.new(), lamport, Kind.REQUEST, body)


class TestDecodedLimits:
    async def test_a_repeated_field_over_its_count_is_refused(self, make_rpc: MakeRpc) -> None:
        client, server = await make_rpc(), await make_rpc()
        seen: list[object] = []
        server.register(ChordFindSuccessor, lambda req: seen.append(req.body) or Ack())
        avoid = (KEY,) * (limits.MAX_COUNT["avoid"] + 1)
        with pytest.raises(
            ProtocolError, match=r"avoid: 1025 elements exceed .*MAX_COUNT\['avoid'\]"
        ):
            await client.request(server.address, ChordFindSuccessor(KEY, avoid))
        assert seen == []
        assert await client.request(server.address, ChordFindSuccessor(KEY, avoid[:3])) == Ack()

    async def test_a_string_over_its_length_is_refused(self, make_rpc: MakeRpc) -> None:
        client, server = await make_rpc(), await make_rpc()
        server.register(Hello, lambda req: Welcome(()))
        member = Member(client.transport.peer_id, "tcp://127.0.0.1:1", "x" * 1025)
        with pytest.raises(ProtocolError, match=r"MAX_TEXT\['name'\]"):
            await client.request(server.address, Hello(member))

    @pytest.mark.parametrize("address", ["garbage", "tcp://", "http://host:80", "tcp://h:1 x"])
    async def test_an_address_that_is_no_peer_address_is_refused(
        self, make_rpc: MakeRpc, address: str
    ) -> None:
        client, server = await make_rpc(), await make_rpc()
        server.register(Hello, lambda req: Welcome(()))
        member = Member(client.transport.peer_id, address)
        with pytest.raises(ProtocolError, match="is not a peer address"):
            await client.request(server.address, Hello(member))

    async def test_an_item_payload_over_its_size_is_refused(
        self, make_rpc: MakeRpc, monkeypatch: pytest.MonkeyPatch
    ) -> None:
        monkeypatch.setitem(limits.MAX_BYTES, "data", 1000)  # as if 16 MiB were 1000 bytes
        client, server = await make_rpc(), await make_rpc()
        server.register(TriggerPush, lambda req: Ack())
        revision = _revision(b"x" * 1001)
        record = CommitRecord(revision.commit_id, 5, revision.author, "", (revision.chunk_id,))
        push = TriggerPush(b"s", record, (revision,))
        with pytest.raises(ProtocolError, match=r"data: 1001 bytes exceed .*MAX_BYTES\['data'\]"):
            await client.request(server.address, push)


class TestLamport:
    async def test_a_time_near_2_64_is_refused_and_not_merged(
        self, make_rpc: MakeRpc, raw_dealer: Callable[[str], zmq.asyncio.Socket]
    ) -> None:
        server = await make_rpc()
        server.register(Ping, lambda req: Pong())
        sock = raw_dealer(server.address)
        before = server.transport.clock.now()
        reply = await _ask(sock, _request(Ping(), lamport=2**64 - 1))
        assert isinstance(reply.body, ErrorReply)
        assert "MAX_LAMPORT" in reply.body.message
        assert server.transport.clock.now() < before + 10  # its own reply ticked it
        assert isinstance((await _ask(sock, _request(Ping(), request_id=8))).body, Pong)

    async def test_a_jump_beyond_max_clock_jump_is_refused(
        self, make_rpc: MakeRpc, raw_dealer: Callable[[str], zmq.asyncio.Socket]
    ) -> None:
        server = await make_rpc()
        server.register(Ping, lambda req: Pong())
        sock = raw_dealer(server.address)
        now = server.transport.clock.now()
        reply = await _ask(sock, _request(Ping(), lamport=now + limits.MAX_CLOCK_JUMP + 10))
        assert isinstance(reply.body, ErrorReply)
        assert "MAX_CLOCK_JUMP" in reply.body.message
        assert server.transport.clock.now() < now + 10
        reply = await _ask(sock, _request(Ping(), lamport=now + 1000, request_id=8))
        assert isinstance(reply.body, Pong)  # a smaller jump is a normal merge
        assert server.transport.clock.now() > now + 1000


class TestFrames:
    async def test_beyond_twice_the_limit_zmq_cuts_the_frame_before_python_sees_it(
        self, make_rpc: MakeRpc, raw_dealer: Callable[[str], zmq.asyncio.Socket]
    ) -> None:
        server = await make_rpc(max_message_size=1024)
        server.register(Ping, lambda req: Pong())
        sock = raw_dealer(server.address)
        await sock.send(codec.encode(_request(Ping(b"x" * 3000))))  # > MAXMSGSIZE (2048)
        # Had the frame reached Python, its ErrorReply would come first on this
        # link; zmq drops the link instead, and the DEALER connects again.
        for request_id in range(100, 200):
            await sock.send(codec.encode(_request(Ping(), request_id=request_id)))
            try:
                async with asyncio.timeout(1):
                    reply = codec.decode(await sock.recv())
            except TimeoutError:
                continue  # sent on the link zmq was dropping
            assert reply.request_id != 7
            assert isinstance(reply.body, Pong)
            break
        else:
            pytest.fail("the server never answered after the oversized frame")
        assert server.transport.stats.dropped_count("oversized") == 0


class TestChord:
    @pytest.fixture
    async def node(self, make_rpc: MakeRpc) -> ChordNode:
        rpc = await make_rpc()
        return ChordNode(rpc, PeerId.new())

    @pytest.mark.parametrize("ttl", [1e12, math.nan, math.inf, 0.0, -1.0])
    async def test_an_absurd_time_to_live_is_refused(
        self, make_rpc: MakeRpc, node: ChordNode, ttl: float
    ) -> None:
        client = await make_rpc()
        with pytest.raises(LimitExceeded, match="MAX_TTL"):
            await client.request(node.rpc.address, ChordAdd(KEY, b"m", ttl))
        entries = (ChordEntry(KEY, b"ok", 30.0), ChordEntry(KEY, b"bad", ttl))
        with pytest.raises(LimitExceeded, match="MAX_TTL"):
            await client.request(node.rpc.address, ChordStore(entries))
        assert len(node.storage) == 0  # not even the good entry before the bad one

    async def test_what_a_node_stores_for_others_has_a_budget(
        self, make_rpc: MakeRpc, node: ChordNode
    ) -> None:
        client = await make_rpc()
        node.storage.capacity = 900
        for i in range(5):
            await client.request(node.rpc.address, ChordAdd(KEY, bytes([i]) * 100, 30.0))
        with pytest.raises(LimitExceeded, match="MAX_NODE_STORAGE_BYTES"):
            await client.request(node.rpc.address, ChordAdd(KEY, b"y" * 100, 30.0))
        assert node.storage.used == 5 * (100 + 64)
        await client.request(node.rpc.address, ChordAdd(KEY, b"\x00" * 100, 30.0))  # a refresh
        node.storage.expire(node.clock() + 31)
        assert node.storage.used == 0
        await client.request(node.rpc.address, ChordAdd(KEY, b"y" * 100, 30.0))


class TestPeerState:
    @pytest.fixture
    async def peer(self, make_peer: Callable[..., Awaitable[Peer]]) -> Peer:
        peer = await make_peer()
        await peer.start("tcp://127.0.0.1:0")
        return peer

    async def test_strangers_with_new_ids_cannot_grow_the_member_list_without_end(
        self, make_rpc: MakeRpc, peer: Peer, monkeypatch: pytest.MonkeyPatch
    ) -> None:
        assert peer.swarm is not None
        monkeypatch.setitem(limits.MAX_COUNT, "members", 3)
        index = peer.grid.config_fingerprint()
        clients = [await make_rpc() for _ in range(3)]
        welcomes = []
        for client in clients[:2]:
            me = Member(client.transport.peer_id, client.address)
            welcomes.append(await client.request(peer.swarm.address, Hello(me, index)))
        assert len(welcomes[-1].members) == 3
        me = Member(clients[2].transport.peer_id, clients[2].address)
        with pytest.raises(LimitExceeded, match=r"MAX_COUNT\['members'\]"):
            await clients[2].request(peer.swarm.address, Hello(me, index))
        again = Member(clients[0].transport.peer_id, clients[0].address)
        assert len((await clients[0].request(peer.swarm.address, Hello(again, index))).members) == 3


class TestBoundedState:
    def test_traffic_of_ever_new_peers_is_counted_together(
        self, monkeypatch: pytest.MonkeyPatch
    ) -> None:
        monkeypatch.setattr(limits, "MAX_STATS_KEYS", 10)
        stats = Stats()
        for i in range(100):
            stats.record_received(f"peer{i}", "ping", 5)
        assert len(stats.received) == 11
        assert stats.received[(OTHERS, "ping")].messages == 90
        assert sum(t.messages for t in stats.received.values()) == 100

    async def test_links_beyond_the_limit_close_the_oldest(
        self, make_rpc: MakeRpc, monkeypatch: pytest.MonkeyPatch
    ) -> None:
        monkeypatch.setattr(limits, "MAX_LINKS", 2)
        client = await make_rpc()
        servers = [await make_rpc() for _ in range(3)]
        for server in servers:
            server.register(Ping, lambda req: Pong())
            assert await client.request(server.address, Ping()) == Pong()
        dealers = client.transport._dealers  # type: ignore[attr-defined]
        assert list(dealers) == [servers[1].address, servers[2].address]
        assert await client.request(servers[0].address, Ping()) == Pong()  # reopened
        assert list(dealers) == [servers[2].address, servers[0].address]

    async def test_a_bad_address_from_the_wire_is_a_usage_error(self, make_rpc: MakeRpc) -> None:
        client = await make_rpc()
        with pytest.raises(UsageError, match="not a peer address"):
            await client.request("tcp://host:port", Ping())


class TestSubscriptions:
    def _subscription(self, where: int = 1, address: str = "tcp://127.0.0.1:1") -> bytes:
        spec = SubscriptionSpec(REGION, None, (("label", "door"),) * where)
        return bytes(spec.to_pb(os.urandom(16), PeerId.new(), address).SerializeToString())

    def test_absurd_filter_counts_and_broken_regions_are_refused(self) -> None:
        assert decode_subscription(self._subscription(where=64)).where
        with pytest.raises(LimitExceeded, match=r"MAX_COUNT\['where'\]"):
            decode_subscription(self._subscription(where=65))
        message = lookup_pb2.Subscription.FromString(self._subscription())
        message.region.xmin = math.nan
        with pytest.raises(ValueError, match="finite"):
            decode_subscription(message.SerializeToString())
        assert not region_filter(encode_filter(REGION))(message.SerializeToString())

    async def test_a_hostile_subscription_in_the_ring_does_not_fail_a_commit(
        self, make_peer: Callable[..., Awaitable[Peer]]
    ) -> None:
        peer = await make_peer()
        await peer.start("tcp://127.0.0.1:0")
        assert peer.swarm is not None
        assert peer.swarm.subscriptions.index is not None
        not_json = lookup_pb2.Subscription.FromString(self._subscription())
        not_json.where[0].equals.number_value = math.nan  # no JSON value: from_pb fails
        hostile = [
            not_json.SerializeToString(),
            self._subscription(address="ipc://"),  # zmq cannot connect to it
            self._subscription(where=65),
        ]
        for key in peer.swarm.subscriptions.index.cell_keys(REGION):
            for member in hostile:
                await peer.swarm.chord.add(key, member, 30.0)
        await peer.create_table("rooms", "google.protobuf.Struct")
        chunk = await peer.create_chunk("rooms")
        item = struct_pb2.Struct()
        item.update({"bbox": [1, 1, 0, 2, 2, 1], "label": "door"})
        tx = peer.begin()
        item_id = tx.insert("rooms", item, chunk)
        record = await tx.commit("inside the hostile subscriptions' region")
        assert record is not None
        assert await peer.begin().get("rooms", item_id) == item
