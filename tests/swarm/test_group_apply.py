"""Big entries apply in a worker thread, in log order, while the loop goes on
(`swarm/group_apply.py`; issue 14 §1): real sockets and SQLite stores, one peer
whose apply hook holds a big entry until the test lets it go."""

from __future__ import annotations

import asyncio
import threading
import time
from pathlib import Path
from typing import ClassVar

from mapapi.core.ids import ChunkId, PeerId
from mapapi.net.codec import Ping, Pong
from mapapi.swarm.group_apply import HEAVY_BYTES
from mapapi.swarm.groups import Applied
from mapapi.swarm.raft_types import Entry
from tests.swarm.raft_world import TIMEOUT, Node, World, leader_of
from tests.swarm.raft_world import world as world  # the fixture

BIG = b"big" + bytes(HEAVY_BYTES)
A = ChunkId.new()


class Gated(Node):
    """A peer whose apply of a big entry waits for `gate`, and notes its thread."""

    gate = threading.Event()
    threads: ClassVar[list[str]] = []

    def __init__(self, world: World, peer: PeerId, path: Path) -> None:
        super().__init__(world, peer, path)
        self.loop = asyncio.get_running_loop()

    def _apply(self, chunk: ChunkId, entry: Entry) -> Applied:
        if entry.data.startswith(b"big"):
            Gated.threads.append(threading.current_thread().name)
            self.loop.call_soon_threadsafe(self.changed.set)  # `wait`ers look again
            assert Gated.gate.wait(TIMEOUT), "the test never opened the gate"
        return super()._apply(chunk, entry)


async def gated(world: World, n: int, chunks: list[ChunkId]) -> list[Node]:
    """`n` gated peers founding `chunks` together, the gate closed."""
    Gated.gate.clear()
    Gated.threads.clear()
    nodes = [await world.add(kind=Gated) for _ in range(n)]
    for chunk in chunks:
        for node in nodes:
            node.groups.found(chunk, [m.id for m in nodes])
    return nodes


async def test_a_big_entry_applies_in_a_worker_while_the_peer_answers(world: World) -> None:
    (node,) = await gated(world, 1, [A])
    other = await world.add()
    big = asyncio.ensure_future(node.groups.propose(A, BIG))
    await node.wait(lambda: bool(Gated.threads))  # the big entry is being applied

    # its loop still answers over the network (a write would wait for SQLite's lock)
    pong = await other.rpc.request(world.addresses[node.id], Ping(b"up?"), expect=Pong)

    assert pong.payload == b"up?"
    assert not big.done()
    assert Gated.threads[0] != threading.main_thread().name
    Gated.gate.set()
    await big
    assert node.applied[A] == [BIG]


async def test_entries_behind_a_big_one_apply_after_it_in_log_order(world: World) -> None:
    nodes = await gated(world, 3, [A])
    leader = await leader_of(nodes, A)
    big = asyncio.ensure_future(leader.groups.propose(A, BIG))
    await leader.wait(lambda: bool(Gated.threads))
    small = asyncio.ensure_future(leader.groups.propose(A, b"after"))
    # the small entry commits, and waits behind the big one: not applied, no answer
    await leader.wait(lambda: all_committed(leader))
    assert not small.done()
    assert A not in leader.applied

    Gated.gate.set()
    await asyncio.gather(big, small)
    for node in nodes:
        await node.wait(lambda node=node: len(node.applied.get(A, [])) == 2)
        assert node.applied[A] == [BIG, b"after"]
    # and every store's applied index follows, once the leader's commit index reached it
    last = leader.groups.applied(A)
    for node in nodes:
        await node.wait(lambda node=node: node.groups.applied(A) == last)


def all_committed(node: Node) -> bool:
    """Whether the leader's log committed every entry it holds of chunk A."""
    log = node.groups._group(A).node.log  # the core's indexes, as this peer knows them
    return log.committed == log.last_index


async def test_a_ready_waits_for_the_write_lock_in_a_worker_not_on_the_loop(world: World) -> None:
    """A worker holds SQLite's write lock (a big entry being applied): the next
    proposal's Ready is written by a worker once the lock is free (`ready_disk.py`),
    and meanwhile the loop answers; both entries then apply in log order."""
    (node,) = await gated(world, 1, [A])
    other = await world.add()
    big = asyncio.ensure_future(node.groups.propose(A, BIG))
    await node.wait(lambda: bool(Gated.threads))  # the worker holds the lock
    small = asyncio.ensure_future(node.groups.propose(A, b"after"))

    pong = await other.rpc.request(world.addresses[node.id], Ping(b"up?"), expect=Pong)

    assert pong.payload == b"up?"
    assert node.groups.disk.busy(A)  # its Ready waits in a worker
    assert not small.done()
    Gated.gate.set()
    await asyncio.gather(big, small)
    assert node.applied[A] == [BIG, b"after"]
    kept = node.store.raft_load(A)
    assert kept is not None
    assert [e.data for e in kept.entries][-2:] == [BIG, b"after"]
    assert not node.groups.disk.busy(A)


COST = 0.015  # seconds one "cost" entry takes to apply (of INLINE_BUDGET_S = 0.02)


class Costly(Node):
    """A peer whose apply of a small "cost" entry takes `COST` seconds of the
    thread it runs in, and notes whether that was the loop's."""

    on_loop: ClassVar[list[bool]] = []

    def _apply(self, chunk: ChunkId, entry: Entry) -> Applied:
        if entry.data.startswith(b"cost"):
            Costly.on_loop.append(threading.current_thread() is threading.main_thread())
            end = time.perf_counter() + COST
            while time.perf_counter() < end:  # work, as decoding and writing rows is
                pass
        return super()._apply(chunk, entry)


async def test_small_entries_of_many_chunks_leave_the_loop_once_it_spent_its_budget(
    world: World,
) -> None:
    """A mission cut into tiles is many small entries decided at once: applied on
    the loop one after another, they held it for a second. The loop applies them
    until it spent `INLINE_BUDGET_S` in one turn; the rest go to workers."""
    Costly.on_loop.clear()
    node = await world.add(kind=Costly)
    chunks = [ChunkId.new() for _ in range(6)]
    for chunk in chunks:
        node.groups.found(chunk, [node.id])
    for chunk in chunks:
        await leader_of([node], chunk)

    # each proposal's task takes its first step in the same turn of the loop
    proposals = [asyncio.ensure_future(node.groups.propose(c, b"cost")) for c in chunks]
    await asyncio.gather(*proposals)

    assert len(Costly.on_loop) == len(chunks)
    assert Costly.on_loop[0]  # the first applies at once, on the loop
    assert 1 <= sum(Costly.on_loop) <= 2  # then the budget is spent: workers take the rest
    assert all(node.applied[c] == [b"cost"] for c in chunks)
