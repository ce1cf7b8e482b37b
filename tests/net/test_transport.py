"""The ZeroMQ transport under hostile input, and its traffic counters."""

from __future__ import annotations

import asyncio
import random
from collections.abc import AsyncIterator

import pytest
import zmq
import zmq.asyncio

from mapapi.core.errors import NetworkError, PeerUnavailable, ProtocolError, RequestTimeout
from mapapi.core.ids import PeerId
from mapapi.net import Ping, Pong, Request, Rpc, ZmqTransport, codec
from mapapi.net.codec import Envelope, ErrorReply, Kind

from .conftest import MakeRpc

_RAW_PEER = PeerId("0f" * 16)


@pytest.fixture
async def raw_context() -> AsyncIterator[zmq.asyncio.Context]:
    """A zmq context for hand-driven sockets; every socket made from it is closed."""
    ctx = zmq.asyncio.Context()
    yield ctx
    ctx.destroy(linger=0)


def _raw_socket(ctx: zmq.asyncio.Context, kind: int) -> zmq.asyncio.Socket:
    sock = ctx.socket(kind)
    sock.setsockopt(zmq.LINGER, 0)
    return sock


def _ping(request_id: int, payload: bytes = b"") -> bytes:
    return codec.encode(Envelope(request_id, _RAW_PEER, 1, Kind.REQUEST, Ping(payload)))


async def _reply_to(sock: zmq.asyncio.Socket, request_id: int) -> list[Envelope]:
    """Every reply up to and including the one for `request_id`.

    A DEALER->ROUTER link keeps order, so once this arrives the server has
    processed everything sent before it.
    """
    replies = []
    async with asyncio.timeout(5):
        while True:
            env = codec.decode(await sock.recv())
            replies.append(env)
            if env.request_id == request_id:
                return replies


def _garbage(seed: int) -> list[bytes]:
    rng = random.Random(seed)
    blobs = [rng.randbytes(rng.randint(0, 300)) for _ in range(50)]
    valid = _ping(99, b"payload")
    blobs += [b"", valid[:-3], valid[:5], b"\x08\x05" + rng.randbytes(40)]
    return blobs


class TestHostileInput:
    @pytest.mark.parametrize("seed", [1, 2, 3])
    async def test_random_bytes_are_counted_and_the_peer_keeps_serving(
        self, pair: tuple[Rpc, Rpc], raw_context: zmq.asyncio.Context, seed: int
    ) -> None:
        client, server = pair
        raw = _raw_socket(raw_context, zmq.DEALER)
        raw.connect(server.address)
        blobs = _garbage(seed)
        for blob in blobs:
            await raw.send(blob)
        await raw.send_multipart([b"two", b"frames"])
        await raw.send(_ping(10_000))
        replies = await _reply_to(raw, 10_000)
        assert replies[-1].body == Pong(b"")
        assert server.transport.stats.dropped_count("malformed") == len(blobs) + 1
        # broken requests whose id could be read were answered with ProtocolError
        errors = [r.body for r in replies[:-1]]
        assert errors
        assert all(isinstance(e, ErrorReply) and e.code == ProtocolError.code for e in errors)
        assert await client.request(server.address, Ping(b"still")) == Pong(b"still")

    async def test_unknown_body_gets_an_error_reply(
        self, pair: tuple[Rpc, Rpc], raw_context: zmq.asyncio.Context
    ) -> None:
        _, server = pair
        raw = _raw_socket(raw_context, zmq.DEALER)
        raw.connect(server.address)
        unknown = _ping(5)
        unknown = unknown[: unknown.index(b"\x5a")] + bytes([0x9A, 0x06, 0x00])  # field 99
        await raw.send(unknown)
        (reply,) = await _reply_to(raw, 5)
        assert isinstance(reply.body, ErrorReply)
        assert codec.error_class(reply.body.code) is ProtocolError

    async def test_oversized_request_is_dropped_counted_and_answered(
        self, make_rpc: MakeRpc, raw_context: zmq.asyncio.Context
    ) -> None:
        server = await make_rpc(max_message_size=1024)
        server.register(Ping, lambda req: Pong())
        raw = _raw_socket(raw_context, zmq.DEALER)
        raw.connect(server.address)
        await raw.send(_ping(3, b"x" * 1500))
        await raw.send(_ping(4))
        replies = await _reply_to(raw, 4)
        assert [r.request_id for r in replies] == [3, 4]
        assert isinstance(replies[0].body, ErrorReply)
        assert "oversized" in replies[0].body.message
        assert server.transport.stats.dropped_count("oversized") == 1

    async def test_oversized_send_is_refused_locally(self, make_rpc: MakeRpc) -> None:
        client = await make_rpc(max_message_size=1024)
        with pytest.raises(ProtocolError, match="exceeds the limit"):
            await client.request(client.address, Ping(b"x" * 2000))

    async def test_broken_reply_fails_the_request_at_once(
        self, make_rpc: MakeRpc, raw_context: zmq.asyncio.Context
    ) -> None:
        client = await make_rpc()
        router = _raw_socket(raw_context, zmq.ROUTER)
        port = router.bind_to_random_port("tcp://127.0.0.1")

        async def answer_with_garbage() -> None:
            routing_id, data = await router.recv_multipart()
            request_id = codec.peek_request_id(data)
            assert request_id is not None
            await router.send_multipart([routing_id, b"\x08" + bytes([request_id]) + b"\xff"])

        server = asyncio.create_task(answer_with_garbage())
        with pytest.raises(ProtocolError, match="undecodable"):
            await client.request(f"tcp://127.0.0.1:{port}", Ping(), timeout=5)
        await server
        assert client.transport.stats.dropped_count("malformed") == 1


class TestStats:
    async def test_bytes_and_messages_per_type_and_peer(self, pair: tuple[Rpc, Rpc]) -> None:
        client, server = pair
        for payload in (b"a", b"bb", b"ccc"):
            await client.request(server.address, Ping(payload))
        out, into = client.transport.stats, server.transport.stats
        assert out.sent_by_type()["ping"].messages == 3
        assert out.sent_by_type()["ping"] == into.received_by_type()["ping"]
        assert into.sent_by_type()["pong"] == out.received_by_type()["pong"]
        assert out.sent_by_type()["ping"].bytes > 3 * 16  # at least the sender ids
        assert list(out.sent_by_peer()) == [server.address]
        assert list(into.received_by_peer()) == [str(client.transport.peer_id)]
        snap = out.snapshot()
        assert snap["sent"][f"{server.address}/ping"]["messages"] == 3
        out.reset()
        assert out.snapshot() == {"sent": {}, "received": {}, "dropped": {}}

    async def test_late_reply_is_counted_as_unmatched(self, make_rpc: MakeRpc) -> None:
        client, server = await make_rpc(), await make_rpc()
        release = asyncio.Event()
        answered: asyncio.Queue[None] = asyncio.Queue()

        async def late(req: Request) -> Pong:
            await release.wait()
            answered.put_nowait(None)  # the reply leaves in this same step
            return Pong()

        server.register(Ping, late)
        with pytest.raises(RequestTimeout):
            await client.request(server.address, Ping(), timeout=0.02)
        release.set()
        await answered.get()
        # replies on one link keep their order: once this one is back, so is the late one
        assert await client.request(server.address, Ping()) == Pong()
        assert client.transport.stats.dropped_count("unmatched") == 1


class TestSockets:
    async def test_one_dealer_per_remote(self, pair: tuple[Rpc, Rpc]) -> None:
        client, server = pair
        for _ in range(3):
            await client.request(server.address, Ping())
        assert isinstance(client.transport, ZmqTransport)
        assert list(client.transport._dealers) == [server.address]

    async def test_bad_address_is_a_caller_mistake(self, make_rpc: MakeRpc) -> None:
        client = await make_rpc()
        with pytest.raises(ValueError, match="not a peer address"):
            await client.request("nonsense", Ping())

    async def test_bind_conflict_is_a_network_error(self, make_rpc: MakeRpc) -> None:
        taken = await make_rpc()
        other = ZmqTransport(PeerId.new())
        with pytest.raises(NetworkError, match="cannot listen"):
            await other.start(taken.address)
        await other.close()

    async def test_shared_context_is_not_terminated(self, raw_context: zmq.asyncio.Context) -> None:
        transport = ZmqTransport(PeerId.new(), context=raw_context)
        await transport.start()
        await transport.close()
        assert not raw_context.closed


class TestLinks:
    async def test_forget_fails_pending_and_reconnects_on_demand(self, make_rpc: MakeRpc) -> None:
        client, server = await make_rpc(), await make_rpc()
        started, release = asyncio.Event(), asyncio.Event()

        async def wait(req: Request) -> Pong:
            started.set()
            await release.wait()
            return Pong(req.body.payload)

        server.register(Ping, wait)
        pending = asyncio.create_task(client.request(server.address, Ping()))
        async with asyncio.timeout(2):
            await started.wait()
        await client.forget(server.address)
        with pytest.raises(PeerUnavailable, match="left"):
            await pending
        release.set()
        assert await client.request(server.address, Ping(b"again")) == Pong(b"again")

    async def test_a_flood_is_drained_in_batches_and_fully_answered(
        self, pair: tuple[Rpc, Rpc], raw_context: zmq.asyncio.Context
    ) -> None:
        _, server = pair
        raw = _raw_socket(raw_context, zmq.DEALER)
        raw.connect(server.address)
        count = 1500  # several reader batches
        for request_id in range(1, count + 1):
            await raw.send(_ping(request_id))
        replies = await _reply_to(raw, count)
        assert [r.request_id for r in replies] == list(range(1, count + 1))
        assert server.transport.stats.received_by_type()["ping"].messages == count
