"""Peers running Raft groups over real sockets, for the group tests: each on
127.0.0.1 with a real SQLite store. A `Node`'s apply hook records what it applied;
a `Ledger` decides commit proposals; a `Writer` also commits transactions through
the logs (`LogCommits`), as a peer will.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Callable
from pathlib import Path

import pytest

from mapapi.core.change import Change, Op
from mapapi.core.clock import LamportClock
from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, ItemId, PeerId
from mapapi.core.table import TableDescriptor
from mapapi.core.transaction import Transaction
from mapapi.net.codec import Ping, Pong
from mapapi.net.rpc import Rpc
from mapapi.net.transport import ZmqTransport
from mapapi.store.sqlite import SqliteStore
from mapapi.swarm.apply_tx import applier
from mapapi.swarm.chunk_state import StoreStates
from mapapi.swarm.group_members import GroupMembers
from mapapi.swarm.groups import COMPACT_AFTER, Applied, RaftGroups
from mapapi.swarm.log_commit import LogCommits
from mapapi.swarm.raft_types import Entry

TIMEOUT = 10.0
OPAQUE = "test.Opaque"
"""The type of the tables here: payloads are raw bytes, of a type this process does
not know, so no leader parses them (`swarm/commit_check.py`)."""
TICK = 0.01  # fast ticks: elections in 0.1-0.2 s


class Node:
    """One peer: an Rpc on 127.0.0.1, a SQLite store and its Raft groups."""

    def __init__(self, world: World, peer: PeerId, path: Path) -> None:
        self.world, self.id, self.path = world, peer, path
        self.store = SqliteStore(path, create=not path.exists())
        self.applied: dict[ChunkId, list[bytes]] = {}
        self.holders: dict[ChunkId, list[PeerId]] = {}  # as the groups' configurations say
        self.changed = asyncio.Event()
        self.rpc = Rpc(ZmqTransport(peer, LamportClock()))
        self.rpc.register(Ping, lambda req: Pong(req.body.payload))  # a leader pings a joiner
        self.groups = RaftGroups(
            peer,
            self.store,
            self.rpc,
            address=lambda p: world.addresses[p],
            apply=self._apply,
            peers=lambda: world.addresses.keys(),
            seed=int(peer.to_bytes()[0]),
            on_change=self.changed.set,
            states=self.states(),
            compact_after=world.compact_after,
            on_members=self.holders.__setitem__,
            alive=world.alive,
            on_applied=lambda chunk, applied: self.changed.set(),  # on the loop
        )

    def states(self) -> StoreStates | None:
        """Nothing to snapshot: this node's "state" is the list of entries it applied."""
        return None

    def _apply(self, chunk: ChunkId, entry: Entry) -> Applied:
        """Record the entry (from a worker thread when it is big: no asyncio here)."""
        self.applied.setdefault(chunk, []).append(entry.data)
        return Applied()

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
        self.compact_after = COMPACT_AFTER  # for the nodes added from now on
        self.alive: Callable[[PeerId], bool] | None = None  # a failure detector: groups go quiet

    async def add(self, peer: PeerId | None = None, kind: type[Node] | None = None) -> Node:
        peer = peer or PeerId.new()
        node = (kind or Node)(self, peer, self.root / f"{peer.short}.sqlite")
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


class Ledger(Node):
    """A peer whose groups decide commit proposals (`swarm/apply.py`)."""

    def states(self) -> StoreStates | None:
        """The chunks' states in the store, as snapshots carry them."""
        return StoreStates(self.store)

    def _apply(self, chunk: ChunkId, entry: Entry) -> Applied:
        return applier(self.store)(chunk, entry)


# -- writers anywhere: a follower's transaction goes to the leader -----------------------
class Writer(Ledger):
    """A peer whose transactions commit through the chunks' logs (`LogCommits`)."""

    def __init__(self, world: World, peer: PeerId, path: Path) -> None:
        super().__init__(world, peer, path)
        self.commits = LogCommits(
            self.groups, self.rpc, lambda p: world.addresses[p], LamportClock()
        )
        self.members = GroupMembers(self.groups, self.rpc, lambda p: world.addresses[p])

    # the TransactionBackend a Transaction needs
    name = "writer"

    def table(self, name: str) -> TableDescriptor:
        return TableDescriptor(name, OPAQUE)

    def chunk_table(self, chunk_id: ChunkId) -> str:
        return self.store.chunk_table(chunk_id)

    def read_local(self, item_id: ItemId, time: int) -> Revision | None:
        return self.store.read(item_id, time)

    async def read(self, item_id: ItemId, time: int) -> Revision | None:
        return self.store.read(item_id, time)

    async def scan(self, time: int, table: str, chunk: ChunkId | None) -> list[Revision]:
        return self.store.scan(time, table, chunk)

    async def catch_up(
        self,
        time: int,
        *,
        item: ItemId | None = None,
        table: str = "",
        chunk: ChunkId | None = None,
    ) -> int:
        return time

    async def commit_transaction(self, tx: Transaction, message: str) -> CommitRecord | None:
        return (await self.commits.commit(tx, message)).record


async def founding_writers(world: World, chunk: ChunkId, table: str) -> tuple[list[Writer], Writer]:
    """Three writers founding `chunk` of `table`; them, and their leader."""
    nodes = [await world.add(kind=Writer) for _ in range(3)]
    for node in nodes:
        node.store.add_table(table, OPAQUE)
        node.store.add_chunk(chunk, table)
        node.groups.found(chunk, [n.id for n in nodes])
    leader = await leader_of(nodes, chunk)
    assert isinstance(leader, Writer)
    return nodes, leader


async def item_group(world: World, chunk: ChunkId, item: ItemId) -> tuple[Writer, Writer]:
    """Three writers founding `chunk` with `item` in it; (a follower, the leader)."""
    nodes, leader = await founding_writers(world, chunk, "t")
    first = Transaction(leader, 0, leader.id)
    first.stage(Change(Op.INSERT, "t", item, chunk, b"0"))
    await first.commit("0")
    follower = next(n for n in nodes if n is not leader)
    assert isinstance(follower, Writer)
    await follower.wait(lambda: follower.groups.leader(chunk) == leader.id)
    await follower.wait(lambda: follower.store.latest([item]) != {})
    return follower, leader
