"""Raft groups over real sockets (DESIGN §13): three peers on 127.0.0.1 share chunk
groups, persist them in real SQLite stores, elect, replicate, fail over and restart.

Each peer's apply hook records the entries it applies, so the tests compare what
every peer applied (one history per chunk) and wait for exactly the event they need.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Callable
from pathlib import Path

import pytest

from mapapi.core.clock import LamportClock
from mapapi.core.errors import RequestTimeout
from mapapi.core.ids import ChunkId, PeerId
from mapapi.net.rpc import Rpc
from mapapi.net.transport import ZmqTransport
from mapapi.store.sqlite import SqliteStore
from mapapi.swarm.groups import NotChunkLeader, RaftGroups
from mapapi.swarm.raft_types import Entry

TIMEOUT = 10.0
TICK = 0.01  # fast ticks: elections in 0.1-0.2 s


class Node:
    """One peer: an Rpc on 127.0.0.1, a SQLite store and its Raft groups."""

    def __init__(self, world: World, peer: PeerId, path: Path) -> None:
        self.world, self.id, self.path = world, peer, path
        self.store = SqliteStore(path, create=not path.exists())
        self.applied: dict[ChunkId, list[bytes]] = {}
        self.changed = asyncio.Event()
        self.rpc = Rpc(ZmqTransport(peer, LamportClock()))
        self.groups = RaftGroups(
            peer,
            self.store,
            self.rpc,
            address=lambda p: world.addresses[p],
            apply=self._apply,
            peers=lambda: world.addresses.keys(),
            seed=int(peer.to_bytes()[0]),
            on_change=self.changed.set,
        )

    def _apply(self, chunk: ChunkId, entry: Entry) -> None:
        self.applied.setdefault(chunk, []).append(entry.data)
        self.changed.set()

    async def start(self) -> None:
        self.world.addresses[self.id] = await self.rpc.start("tcp://127.0.0.1:0")
        self.groups.start(TICK)

    async def stop(self) -> None:
        await self.groups.close()
        await self.rpc.close()
        self.store.close()

    async def wait(self, predicate: Callable[[], bool]) -> None:
        """Until `predicate` holds, re-checked after every applied entry and every
        round of this node's groups that changed a role or sent messages."""
        async with asyncio.timeout(TIMEOUT):
            while not predicate():
                self.changed.clear()
                await self.changed.wait()


class World:
    """The peers of one test, and where each is reached."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.addresses: dict[PeerId, str] = {}
        self.nodes: list[Node] = []

    async def add(self, peer: PeerId | None = None) -> Node:
        peer = peer or PeerId.new()
        node = Node(self, peer, self.root / f"{peer.short}.sqlite")
        await node.start()
        self.nodes.append(node)
        return node


@pytest.fixture
async def world(tmp_path: Path) -> AsyncIterator[World]:
    made = World(tmp_path)
    yield made
    for node in made.nodes:
        await node.stop()


async def leader_of(nodes: list[Node], chunk: ChunkId) -> Node:
    """The node that leads `chunk` once an election settled."""
    await nodes[0].wait(lambda: sum(n.groups.is_leader(chunk) for n in nodes) == 1)
    return next(n for n in nodes if n.groups.is_leader(chunk))


async def propose_all(leader: Node, chunk: ChunkId, values: list[bytes]) -> None:
    """Propose every value at once (pipelined) and wait for all to apply."""
    await asyncio.gather(*(leader.groups.propose(chunk, v) for v in values))


async def founded(world: World, chunks: list[ChunkId], n: int = 3) -> list[Node]:
    nodes = [await world.add() for _ in range(n)]
    for chunk in chunks:
        for node in nodes:
            node.groups.found(chunk, [m.id for m in nodes])
    return nodes


CHUNK = ChunkId.new()


async def test_a_group_of_three_applies_one_history(world: World) -> None:
    nodes = await founded(world, [CHUNK])
    leader = await leader_of(nodes, CHUNK)
    values = [f"v{i}".encode() for i in range(50)]
    await propose_all(leader, CHUNK, values)
    for node in nodes:
        await node.wait(lambda node=node: len(node.applied.get(CHUNK, [])) == len(values))
    assert {tuple(n.applied[CHUNK]) for n in nodes} == {tuple(leader.applied[CHUNK])}
    assert sorted(leader.applied[CHUNK]) == sorted(values)


async def test_a_follower_refuses_a_proposal_naming_the_leader(world: World) -> None:
    nodes = await founded(world, [CHUNK])
    leader = await leader_of(nodes, CHUNK)
    follower = next(n for n in nodes if n is not leader)
    await follower.wait(lambda: follower.groups.leader(CHUNK) == leader.id)
    with pytest.raises(NotChunkLeader, match=leader.id.short):
        await follower.groups.propose(CHUNK, b"x")


async def test_the_survivors_elect_and_commit_after_the_leader_dies(world: World) -> None:
    nodes = await founded(world, [CHUNK])
    leader = await leader_of(nodes, CHUNK)
    await propose_all(leader, CHUNK, [b"before"])
    await leader.stop()
    world.nodes.remove(leader)
    survivors = [n for n in nodes if n is not leader]
    successor = await leader_of(survivors, CHUNK)
    await propose_all(successor, CHUNK, [b"after"])
    for node in survivors:
        await node.wait(lambda node=node: node.applied.get(CHUNK, [])[-1:] == [b"after"])
        assert node.applied[CHUNK] == [b"before", b"after"]


async def test_a_minority_cannot_commit(world: World) -> None:
    nodes = await founded(world, [CHUNK])
    leader = await leader_of(nodes, CHUNK)
    for node in [n for n in nodes if n is not leader]:
        await node.stop()
        world.nodes.remove(node)
    # CheckQuorum deposes the leader once it hears from no majority; until then its
    # proposal cannot commit either: one way or the other, nothing is acknowledged.
    with pytest.raises((RequestTimeout, NotChunkLeader)):
        await leader.groups.propose(CHUNK, b"lost", timeout=1.0)
    assert b"lost" not in leader.applied.get(CHUNK, [])


async def test_a_restarted_peer_resumes_from_its_store_and_applies_nothing_twice(
    world: World,
) -> None:
    nodes = await founded(world, [CHUNK])
    leader = await leader_of(nodes, CHUNK)
    await propose_all(leader, CHUNK, [b"a", b"b"])
    follower = next(n for n in nodes if n is not leader)
    await follower.wait(lambda: len(follower.applied.get(CHUNK, [])) == 2)
    await follower.stop()
    world.nodes.remove(follower)
    await propose_all(leader, CHUNK, [b"c"])  # two of three voters still commit
    again = await world.add(follower.id)  # same store, a new port
    assert again.groups.resume(CHUNK)
    await again.wait(lambda: again.applied.get(CHUNK) == [b"c"])
    assert again.groups.applied(CHUNK) == leader.groups.applied(CHUNK)


async def test_many_groups_share_one_frame_per_pair_of_peers(world: World) -> None:
    chunks = [ChunkId.new() for _ in range(20)]
    nodes = await founded(world, chunks)
    for chunk in chunks:
        await leader_of(nodes, chunk)
    for node in nodes:
        node.groups.frames_sent = node.groups.messages_sent = 0
    await nodes[0].wait(lambda: nodes[0].groups.frames_sent >= 20)  # heartbeats flow
    # Every node leads some of the 20 groups and follows the rest: each frame carries
    # the heartbeats (or their answers) of several groups, not one frame per group.
    for node in nodes:
        assert node.groups.messages_sent >= 3 * node.groups.frames_sent
