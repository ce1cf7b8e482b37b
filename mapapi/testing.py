"""Pytest plugin: fixtures that build real peers and repositories and clean up.

Registered through the `pytest11` entry point, so `mapctl` tests and users'
own test suites get them too. Their peers are the application's (`mapapi.app`):
they keep the map tables' rules, as `mapctl` and the daemon's do.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import AsyncIterator, Awaitable, Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from mapapi.app import memory_peer as app_memory_peer
from mapapi.app import peer_of
from mapapi.lookup.spatial import SpatialGrid
from mapapi.service.peer import Peer
from mapapi.service.repo import Repository


def wait_until(predicate: Callable[[], bool], timeout: float = 5.0, interval: float = 0.01) -> None:
    """Block until `predicate()` holds; fail naming the predicate after `timeout` s.

    For cross-process state where no event can be awaited (a child's file, a
    socket); in-process code should await the event that proves the state.
    """
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            name = getattr(predicate, "__name__", repr(predicate))
            raise AssertionError(f"timed out after {timeout}s waiting for {name}")
        time.sleep(interval)  # sync-ok: polling another process's state


async def until(predicate: Callable[[], bool], timeout: float = 5.0) -> None:  # noqa: ASYNC109
    """Await until `predicate()` holds, letting the event loop run between checks;
    fail naming the predicate after `timeout` s.

    For in-process state that changes in background tasks with no event to
    await (a failure detector's verdict, an eviction at another peer).
    """
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            name = getattr(predicate, "__name__", repr(predicate))
            raise AssertionError(f"timed out after {timeout}s waiting for {name}")
        await asyncio.sleep(0.01)  # sync-ok: polling state that has no event


@pytest.fixture
def make_repo(tmp_path: Path) -> Callable[..., Repository]:
    """Factory of initialised repositories under the test's temp folder
    (`secure=True`: with a keypair and an empty trust list)."""
    counter = iter(range(1_000_000))

    def _make(
        name: str | None = None, spatial: SpatialGrid | None = None, *, secure: bool = False
    ) -> Repository:
        index = next(counter)
        return Repository.init(
            tmp_path / f"repo{index}", name or f"peer{index}", spatial, secure=secure
        )

    return _make


@pytest.fixture
async def make_peer(
    make_repo: Callable[..., Repository],
) -> AsyncIterator[Callable[..., Awaitable[Peer]]]:
    """Factory of peers on real SQLite repositories; all are closed after the test."""
    peers: list[Peer] = []

    async def _make(
        name: str | None = None, spatial: SpatialGrid | None = None, *, secure: bool = False
    ) -> Peer:
        repo = make_repo(name, spatial, secure=secure)
        peer = peer_of(repo)
        peers.append(peer)
        return peer

    yield _make
    for peer in peers:
        await peer.close()


@pytest.fixture
def memory_peer() -> Iterator[Peer]:
    """A scratch peer on an in-memory store."""
    peer = app_memory_peer()
    yield peer
    peer.store.close()


@pytest.fixture
async def raw_dealer() -> AsyncIterator[Callable[[str], Any]]:
    """Factory of hand-driven zmq DEALER sockets (`zmq.asyncio.Socket`) connected to
    an address, for sending a peer bytes no `Rpc` would; all closed after the test."""
    import zmq
    import zmq.asyncio

    ctx = zmq.asyncio.Context()
    sockets: list[zmq.asyncio.Socket] = []

    def _connect(address: str) -> zmq.asyncio.Socket:
        sock = ctx.socket(zmq.DEALER)
        sock.setsockopt(zmq.LINGER, 0)
        sock.connect(address)
        sockets.append(sock)
        return sock

    yield _connect
    for sock in sockets:
        sock.close(linger=0)
    ctx.term()
