"""Fixtures for the net tests: RPC peers on 127.0.0.1 port 0, and a sleep guard.

The guard fails a test that synchronises with `time.sleep` / `asyncio.sleep`
(STYLE §7) unless the calling line is marked `# sync-ok`.
"""

from __future__ import annotations

from collections.abc import AsyncIterator, Awaitable, Callable
from typing import Any

import pytest

from mapapi.core.clock import LamportClock
from mapapi.core.ids import PeerId
from mapapi.net import Ping, Pong, Request, Rpc, Shaper, ZmqTransport

MakeRpc = Callable[..., Awaitable[Rpc]]


@pytest.fixture
async def make_rpc() -> AsyncIterator[MakeRpc]:
    """Factory of started `Rpc`s on 127.0.0.1 port 0; all closed after the test."""
    made: list[Rpc] = []

    async def _make(
        *,
        clock: LamportClock | None = None,
        max_message_size: int | None = None,
        shaper: Shaper | None = None,
        default_timeout: float = 2.0,
    ) -> Rpc:
        kwargs: dict[str, Any] = {"shaper": shaper}
        if max_message_size is not None:
            kwargs["max_message_size"] = max_message_size
        transport = ZmqTransport(PeerId.new(), clock or LamportClock(), **kwargs)
        rpc = Rpc(transport, default_timeout=default_timeout)
        made.append(rpc)
        await rpc.start("tcp://127.0.0.1:0")
        return rpc

    yield _make
    for rpc in made:
        await rpc.close()


def echo(req: Request) -> Pong:
    """An inline Ping handler."""
    return Pong(req.body.payload)


@pytest.fixture
async def pair(make_rpc: MakeRpc) -> tuple[Rpc, Rpc]:
    """(client, server); the server answers Ping with Pong inline."""
    client, server = await make_rpc(), await make_rpc()
    server.register(Ping, echo)
    return client, server
