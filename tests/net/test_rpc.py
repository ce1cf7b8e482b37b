"""Requests, replies, deadlines, concurrent handlers and shutdown over real sockets."""

from __future__ import annotations

import asyncio
import gc
import logging
import warnings

import pytest

from mapapi.core.clock import LamportClock
from mapapi.core.errors import (
    LockTimeout,
    MapError,
    PeerUnavailable,
    ProtocolError,
    RequestTimeout,
)
from mapapi.core.ids import PeerId
from mapapi.net import Ping, Pong, Request, Rpc
from mapapi.net.codec import Envelope, Kind
from mapapi.net.inbound import Inbound, Route
from mapapi.net.rpc import DEFAULT_TIMEOUT

from .conftest import MakeRpc


class TestRequestResponse:
    async def test_ping_pong(self, pair: tuple[Rpc, Rpc]) -> None:
        client, server = pair
        assert await client.request(server.address, Ping(b"hi"), expect=Pong) == Pong(b"hi")
        assert client.pending == 0

    async def test_a_reply_from_another_peer_than_named_is_refused(
        self, pair: tuple[Rpc, Rpc]
    ) -> None:
        client, server = pair
        real = server.transport.peer_id
        assert await client.request(server.address, Ping(b"x"), expect=Pong, sender=real)
        claimed = PeerId.new()  # a peer that says it is reached at the server's address
        with pytest.raises(ProtocolError, match=f"answered as peer {real.short}, not"):
            await client.request(server.address, Ping(b"y"), expect=Pong, sender=claimed)
        assert client.pending == 0

    async def test_bound_address_is_real(self, pair: tuple[Rpc, Rpc]) -> None:
        _, server = pair
        assert server.address.startswith("tcp://127.0.0.1:")
        assert not server.address.endswith(":0")

    async def test_many_concurrent_requests(self, pair: tuple[Rpc, Rpc]) -> None:
        client, server = pair
        payloads = [str(i).encode() for i in range(200)]
        replies = await asyncio.gather(*(client.request(server.address, Ping(p)) for p in payloads))
        assert replies == [Pong(p) for p in payloads]

    async def test_requests_both_ways(self, make_rpc: MakeRpc) -> None:
        a, b = await make_rpc(), await make_rpc()
        for rpc in (a, b):
            rpc.register(Ping, lambda req: Pong(req.body.payload))
        assert await a.request(b.address, Ping(b"ab")) == Pong(b"ab")
        assert await b.request(a.address, Ping(b"ba")) == Pong(b"ba")

    async def test_async_handler_sees_the_sender(self, make_rpc: MakeRpc) -> None:
        client, server = await make_rpc(), await make_rpc()

        async def who(req: Request) -> Pong:
            return Pong(str(req.sender).encode())

        server.register(Ping, who)
        reply = await client.request(server.address, Ping(), expect=Pong)
        assert reply.payload.decode() == client.transport.peer_id

    async def test_unexpected_reply_type(self, make_rpc: MakeRpc) -> None:
        client, server = await make_rpc(), await make_rpc()
        server.register(Ping, lambda req: Ping(b"not a pong"))
        with pytest.raises(ProtocolError, match="expected pong"):
            await client.request(server.address, Ping(), expect=Pong)

    async def test_a_body_without_handler_is_refused(self, pair: tuple[Rpc, Rpc]) -> None:
        client, server = pair
        with pytest.raises(ProtocolError, match="does not serve pong"):
            await client.request(server.address, Pong())
        assert server.transport.stats.dropped_count("unhandled") == 1

    def test_register_twice_or_unknown_type(self, pair: tuple[Rpc, Rpc]) -> None:
        _, server = pair
        with pytest.raises(ValueError, match="already has a handler"):
            server.register(Ping, lambda req: Pong())
        with pytest.raises(TypeError):
            server.register(str, lambda req: Pong())

    async def test_notify_runs_the_handler_and_gets_no_reply(self, make_rpc: MakeRpc) -> None:
        client, server = await make_rpc(), await make_rpc()
        got: asyncio.Queue[bytes] = asyncio.Queue()
        server.register(Ping, lambda req: got.put_nowait(req.body.payload))
        client.notify(server.address, Ping(b"one-way"))
        async with asyncio.timeout(2):
            assert await got.get() == b"one-way"
        assert server.transport.stats.sent == {}


class TestDeadlines:
    async def test_silent_handler_times_out(self, make_rpc: MakeRpc) -> None:
        client, server = await make_rpc(), await make_rpc()
        never = asyncio.Event()

        async def stuck(req: Request) -> Pong:
            await never.wait()
            return Pong()

        server.register(Ping, stuck)
        with pytest.raises(RequestTimeout, match=r"within 0\.05 s") as info:
            await client.request(server.address, Ping(), timeout=0.05)
        assert info.value.retriable
        assert client.pending == 0

    async def test_nobody_listening_times_out(self, make_rpc: MakeRpc) -> None:
        client, gone = await make_rpc(), await make_rpc()
        address = gone.address
        await gone.close()
        with pytest.raises(RequestTimeout):
            await client.request(address, Ping(), timeout=0.05)

    def test_default_deadline_exists(self) -> None:
        assert 0 < DEFAULT_TIMEOUT < 60


class TestConcurrentHandlers:
    async def test_slow_handler_does_not_block_a_fast_one(self, make_rpc: MakeRpc) -> None:
        client, server = await make_rpc(), await make_rpc()
        slow_started, release = asyncio.Event(), asyncio.Event()

        async def handler(req: Request) -> Pong:
            if req.body.payload == b"slow":
                slow_started.set()
                await release.wait()
            return Pong(req.body.payload)

        server.register(Ping, handler)
        slow = asyncio.create_task(client.request(server.address, Ping(b"slow")))
        async with asyncio.timeout(2):
            await slow_started.wait()
        assert await client.request(server.address, Ping(b"fast")) == Pong(b"fast")
        assert not slow.done()
        release.set()
        assert await slow == Pong(b"slow")


class TestRemoteErrors:
    async def test_map_error_arrives_as_its_class(self, make_rpc: MakeRpc) -> None:
        client, server = await make_rpc(), await make_rpc()

        async def refuse(req: Request) -> Pong:
            raise LockTimeout("chunk c1 is write-locked; retry later")

        server.register(Ping, refuse)
        with pytest.raises(LockTimeout, match="write-locked") as info:
            await client.request(server.address, Ping())
        assert info.value.retriable

    async def test_inline_handler_error_arrives_too(self, make_rpc: MakeRpc) -> None:
        client, server = await make_rpc(), await make_rpc()

        def refuse(req: Request) -> Pong:
            raise LockTimeout("inline")

        server.register(Ping, refuse)
        with pytest.raises(LockTimeout, match="inline"):
            await client.request(server.address, Ping())

    async def test_unexpected_exception_is_logged_and_generic(
        self, make_rpc: MakeRpc, caplog: pytest.LogCaptureFixture
    ) -> None:
        client, server = await make_rpc(), await make_rpc()

        async def broken(req: Request) -> Pong:
            if req.body.payload == b"boom":
                raise ZeroDivisionError("oops")
            return Pong(req.body.payload)

        server.register(Ping, broken)
        with (
            caplog.at_level(logging.ERROR, logger="mapapi.net.rpc"),
            pytest.raises(MapError, match="ZeroDivisionError") as info,
        ):
            await client.request(server.address, Ping(b"boom"))
        assert type(info.value) is MapError
        assert "handler for ping" in caplog.text
        assert await client.request(server.address, Ping(b"ok")) == Pong(b"ok")


async def held_request(
    make_rpc: MakeRpc,
    timeout: float,  # noqa: ASYNC109 (the request's own deadline)
) -> tuple[Rpc, Rpc, asyncio.Event, asyncio.Task[object]]:
    """A client's request whose handler on the server has started and waits until
    the returned event is set (then answers `Pong(b"done")`): (client, server,
    the event, the client's pending request)."""
    client, server = await make_rpc(), await make_rpc()
    started, release = asyncio.Event(), asyncio.Event()

    async def held(req: Request) -> Pong:
        started.set()
        await release.wait()
        return Pong(b"done")

    server.register(Ping, held)
    pending = asyncio.create_task(client.request(server.address, Ping(), timeout=timeout))
    async with asyncio.timeout(2):
        await started.wait()
    return client, server, release, pending


class TestShutdown:
    async def test_close_fails_pending_and_leaves_no_tasks(self, make_rpc: MakeRpc) -> None:
        client, server, _, pending = await held_request(make_rpc, timeout=5)
        await client.close()
        with pytest.raises(PeerUnavailable):
            await pending
        await server.close()
        assert server.running_handlers == 0
        assert asyncio.all_tasks() == {asyncio.current_task()}

    async def test_a_handler_running_at_close_answers_within_the_grace(
        self, make_rpc: MakeRpc
    ) -> None:
        """`peer stop`: the handler of the call that asked for the close is still
        running when the close comes; its answer must go out, not be cancelled."""
        _, server, release, answer = await held_request(make_rpc, timeout=5)
        closing = asyncio.create_task(server.close(grace=5))
        release.set()
        assert await answer == Pong(b"done")
        await closing
        assert server.running_handlers == 0

    async def test_a_handler_still_running_after_the_grace_is_cancelled(
        self, make_rpc: MakeRpc
    ) -> None:
        _, server, _, pending = await held_request(make_rpc, timeout=0.5)
        await server.close(grace=0.01)
        assert server.running_handlers == 0
        with pytest.raises(RequestTimeout):
            await pending

    async def test_a_request_that_arrives_as_it_closes_leaves_no_coroutine_unawaited(
        self, make_rpc: MakeRpc
    ) -> None:
        """The reader hands over a request and close() runs in the same loop turn:
        the handler's task is cancelled before its first step, and its coroutine
        must be closed with it, not dropped ("coroutine ... was never awaited")."""
        server = await make_rpc()
        served: list[Request] = []

        async def handler(req: Request) -> Pong:
            served.append(req)
            return Pong()

        server.register(Ping, handler)
        late = Envelope(1, PeerId.new(), 1, Kind.REQUEST, Ping(b"late"))
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            server.on_message(Inbound(late, Route(b"late", "late"), None, 0))  # as a reader does
            await server.close()
            gc.collect()
        assert served == []
        assert [str(w.message) for w in caught if "never awaited" in str(w.message)] == []

    async def test_requests_after_close_fail_fast(self, pair: tuple[Rpc, Rpc]) -> None:
        client, server = pair
        await client.close()
        await client.close()  # idempotent
        with pytest.raises(PeerUnavailable):
            await client.request(server.address, Ping())
        with pytest.raises(PeerUnavailable):
            client.notify(server.address, Ping())


class TestLamport:
    async def test_clocks_merge_across_a_request(self, make_rpc: MakeRpc) -> None:
        client = await make_rpc(clock=LamportClock(0))
        server = await make_rpc(clock=LamportClock(100))
        server.register(Ping, lambda req: Pong())
        await client.request(server.address, Ping())
        # client ticks to 1 on send; server merges to 101 and ticks to 102 on
        # reply; client merges to 103: one tick per send, one merge per receive.
        assert server.transport.clock.now() == 102
        assert client.transport.clock.now() == 103

    async def test_handler_sees_the_sender_time(self, make_rpc: MakeRpc) -> None:
        client = await make_rpc(clock=LamportClock(50))
        server = await make_rpc()
        seen: list[int] = []

        def record(req: Request) -> Pong:
            seen.append(req.lamport)
            return Pong()

        server.register(Ping, record)
        await client.request(server.address, Ping())
        assert seen == [51]
