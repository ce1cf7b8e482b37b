"""Fixtures for the net tests: RPC peers on 127.0.0.1 port 0, and a sleep guard.

The guard fails a test that synchronises with `time.sleep` / `asyncio.sleep`
(STYLE §7) unless the calling line is marked `# sync-ok`.
"""

from __future__ import annotations

import asyncio
import linecache
import sys
import time
from collections.abc import AsyncIterator, Awaitable, Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from mapapi.clock import LamportClock
from mapapi.ids import PeerId
from mapapi.net import Ping, Pong, Request, Rpc, Shaper, ZmqTransport

_TESTS = str(Path(__file__).resolve().parents[1])

MakeRpc = Callable[..., Awaitable[Rpc]]


@pytest.fixture(autouse=True)
def no_sleep_sync(monkeypatch: pytest.MonkeyPatch) -> Iterator[list[str]]:
    """Record sleeps called from test code; fail the test if any is unmarked."""
    calls: list[str] = []
    real_async, real_time = asyncio.sleep, time.sleep

    def check(delay: float) -> None:
        frame = sys._getframe(2)
        where = frame.f_code.co_filename
        marked = "# sync-ok" in linecache.getline(where, frame.f_lineno)
        if delay > 0 and where.startswith(_TESTS) and not marked:
            calls.append(f"{where}:{frame.f_lineno}")

    def async_sleep(delay: float, result: Any = None) -> Any:
        check(delay)
        return real_async(delay, result)

    def time_sleep(delay: float) -> None:
        check(delay)
        real_time(delay)

    monkeypatch.setattr(asyncio, "sleep", async_sleep)
    monkeypatch.setattr(time, "sleep", time_sleep)
    yield calls
    assert not calls, f"sleep used as synchronisation at {calls}; await an event instead"


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
