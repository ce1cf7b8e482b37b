"""Swarm fixtures and helpers: real peers on real SQLite repositories, on 127.0.0.1 port 0.

Every peer of a test lives in this one process and event loop; they talk over
real zmq sockets. A guard fails any test that synchronises with
`time.sleep` / `asyncio.sleep` (STYLE §7) unless the calling line is marked
`# sync-ok`: tests await the event that proves a state instead.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable, Sequence

import pytest

from mapapi import ChunkId, ConflictError, ItemId, NetworkError, Peer
from mapapi._pb.mapapi.v1.types_pb2 import Account, Counter
from mapapi.lookup.dht.ring import SortedRing
from mapapi.swarm.node import ChordOptions
from mapapi.swarm.node import Swarm as PeerSwarm

TABLE = "counters"
ACCOUNTS = "accounts"

MakeSwarm = Callable[..., Awaitable[list[Peer]]]

__all__ = ["ACCOUNTS", "TABLE", "Account", "Counter", "MakeSwarm"]


@pytest.fixture
def swarm(make_peer: Callable[..., Awaitable[Peer]]) -> MakeSwarm:
    """Factory: n started peers, all joined through the first."""

    async def _swarm(n: int) -> list[Peer]:
        peers = [await make_peer() for _ in range(n)]
        for peer in peers:
            await peer.start("tcp://127.0.0.1:0")
        for peer in peers[1:]:
            await peer.join(peers[0].address)
        return peers

    return _swarm


# -- helpers -------------------------------------------------------------------------


def net(peer: Peer) -> PeerSwarm:
    """The networked side of a started peer."""
    assert peer.swarm is not None, "start the peer first"
    return peer.swarm


async def counter_chunk(
    peer: Peer, value: int = 0, *, table: str = TABLE, name: str = "c"
) -> tuple[ChunkId, ItemId]:
    """A new chunk (creating `table` if needed) holding one counter at `value`."""
    if table not in peer.store.tables():
        await peer.create_table(table, Counter)
    chunk = await peer.create_chunk(table)
    tx = peer.begin()
    item = tx.insert(table, Counter(name=name, value=value), chunk)
    await tx.commit(f"create {name}")
    return chunk, item


async def value(peer: Peer, item: ItemId, at: int | None = None, *, table: str = TABLE) -> int:
    """A counter's value as a transaction begun now (or at `at`) on `peer` reads it."""
    message = await peer.begin(at).get(table, item)
    assert message is not None, f"no item {item.short} on {peer.name}"
    return int(message.value)


async def share(chunk: ChunkId, peers: Sequence[Peer]) -> None:
    """Make every peer of `peers` a holder of `chunk` (one after the other)."""
    for peer in peers:
        await peer.participate(chunk)


async def increment(
    peer: Peer, items: Sequence[tuple[str, ItemId]], message: str = "increment"
) -> int:
    """Add 1 to each (table, item) in one transaction, retried on conflicts and
    lock timeouts until it commits; returns the number of retries."""
    retries = 0
    while True:
        tx = peer.begin()
        for table, item in items:
            current = await tx.get(table, item)
            assert current is not None
            tx.update(table, item, Counter(name=current.name, value=current.value + 1))
        try:
            await tx.commit(message)
        except (ConflictError, NetworkError):
            retries += 1
            continue
        return retries


async def log_ids(peer: Peer) -> list[str]:
    """The ids of every commit in a peer's log, newest first, once its replicas
    caught up with their chunks' leaders (a commit returns once a majority holds
    it, before every holder applied it)."""
    for chunk in peer.chunks():
        await net(peer).groups.catch_up(chunk.id)
    return [str(c.id) for c in peer.log()]


# -- swarms on a settled Chord ring (lookup tests) ----------------------------------

FAST = ChordOptions(
    stabilize=0.02, fix_fingers=0.1, check_predecessor=0.05, timeout=1.0, holder_ttl=5.0
)
MAX_ROUNDS = 1_000

MakePeer = Callable[..., Awaitable[Peer]]


def _ring_correct(peers: list[Peer]) -> bool:
    nodes = [net(p).chord for p in peers]
    oracle = SortedRing(n.key for n in nodes)
    for node in nodes:
        want = oracle.successor_list(node.key, FAST.successors)
        if [s.key for s in node.successors] != want:
            return False
        if len(nodes) > 1 and (
            node.predecessor is None or node.predecessor.key != oracle.predecessor(node.key)
        ):
            return False
    return True


async def lookup_swarm(make_peer: MakePeer, n: int, **options: object) -> list[Peer]:
    """n started peers joined through the first, once their ring is correct
    (`options` go to `make_peer`)."""
    peers = [await make_peer(**options) for _ in range(n)]
    for peer in peers:
        await peer.start("tcp://127.0.0.1:0", chord=FAST)
    for peer in peers[1:]:
        await peer.join(peers[0].address)
    for _ in range(MAX_ROUNDS):
        if _ring_correct(peers):
            return peers
        await net(peers[0]).chord.next_round()
    raise AssertionError(f"the ring of {n} peers did not settle in {MAX_ROUNDS} rounds")
