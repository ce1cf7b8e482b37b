"""Swarm fixtures: real peers on real SQLite repositories, on 127.0.0.1 port 0."""

from __future__ import annotations

from collections.abc import Awaitable, Callable

import pytest

from mapapi import Peer


@pytest.fixture
def swarm(
    make_peer: Callable[..., Awaitable[Peer]],
) -> Callable[[int], Awaitable[list[Peer]]]:
    """Factory: n started peers, all joined through the first."""

    async def _swarm(n: int, lease: float = 5.0) -> list[Peer]:
        peers = [await make_peer() for _ in range(n)]
        for peer in peers:
            await peer.start("tcp://127.0.0.1:0", lease=lease)
        for peer in peers[1:]:
            await peer.join(peers[0].address)
        return peers

    return _swarm
