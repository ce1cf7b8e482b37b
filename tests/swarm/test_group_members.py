"""Holders come and go through the chunk's log, over real sockets (DESIGN §13):
joining through any member, leaving (the leader too), and a dead member removed by
the leader after a while, never by a peer on its own."""

from __future__ import annotations

import asyncio

import pytest

from mapapi.core.change import Change, Op
from mapapi.core.ids import ChunkId, ItemId, PeerId
from mapapi.core.transaction import Transaction
from mapapi.swarm import group_members
from mapapi.swarm.group_members import REMOVE_AFTER
from mapapi.swarm.raft_wire import node_id
from tests.swarm.raft_world import OPAQUE, World, Writer, leader_of
from tests.swarm.raft_world import world as world  # the fixture

CHUNK = ChunkId.new()
ITEM = ItemId.new()


async def group(world: World) -> tuple[list[Writer], Writer]:
    nodes = [await world.add(kind=Writer) for _ in range(3)]
    for node in nodes:
        node.store.add_table("t", OPAQUE)
        node.store.add_chunk(CHUNK, "t")
        node.groups.found(CHUNK, [n.id for n in nodes])
    leader = await leader_of(nodes, CHUNK)  # type: ignore[arg-type]
    await write(leader, b"0")  # type: ignore[arg-type]
    for node in nodes:
        await node.wait(lambda n=node: n.groups.leader(CHUNK) == leader.id)
    return nodes, leader  # type: ignore[return-value]


async def write(node: Writer, data: bytes) -> None:
    tx = Transaction(node, node.store.raft_time(CHUNK), node.id)
    op = Op.INSERT if node.store.latest([ITEM]) == {} else Op.UPDATE
    tx.stage(Change(op, "t", ITEM, CHUNK, data))
    await tx.commit(data.decode())


def value(node: Writer) -> bytes:
    return node.store.latest([ITEM])[ITEM].data


async def test_a_peer_joins_through_any_member_and_arrives_with_the_state(
    world: World,
) -> None:
    nodes, leader = await group(world)
    follower = next(n for n in nodes if n is not leader)
    late = await world.add(kind=Writer)
    changed = await late.members.join(CHUNK, via=follower.id)  # asked there, done by the leader
    assert late.id in changed.members
    assert value(late) == b"0"  # its replica is up to the change that added it
    assert (
        node_id(late.id) in leader.groups.config(CHUNK).learners
    )  # 4 holders: 3 voters, 1 learner
    for node in [*nodes, late]:
        await node.wait(lambda n=node: late.id in n.holders.get(CHUNK, []))
    await write(late, b"1")  # a learner commits through the leader
    for node in nodes:
        await node.wait(lambda n=node: value(n) == b"1")


async def test_a_holder_leaves_and_the_others_go_on(world: World) -> None:
    nodes, leader = await group(world)
    leaving = next(n for n in nodes if n is not leader)
    await leaving.members.leave(CHUNK)
    assert leaving.store.raft_load(CHUNK) is None
    assert node_id(leaving.id) not in leader.groups.config(CHUNK).members
    await write(leader, b"after")


async def test_the_leader_leaves_and_hands_its_group_over(world: World) -> None:
    nodes, leader = await group(world)
    await leader.members.leave(CHUNK)
    rest = [n for n in nodes if n is not leader]
    successor = await leader_of(rest, CHUNK)  # type: ignore[arg-type]
    assert node_id(leader.id) not in successor.groups.config(CHUNK).members
    assert await successor.members.reap(lambda p: False, now=0.0) == []  # type: ignore[attr-defined]
    assert len(successor.groups.config(CHUNK).voters) == 1  # two holders: a voter, a learner
    await write(successor, b"after")  # type: ignore[arg-type]
    other = next(n for n in rest if n is not successor)
    await other.wait(lambda: value(other) == b"after")  # type: ignore[arg-type]


async def test_a_dead_member_is_removed_by_the_leader_only_after_a_while(world: World) -> None:
    nodes, leader = await group(world)
    dead = next(n for n in nodes if n is not leader)
    await dead.stop()
    world.nodes.remove(dead)
    assert await leader.members.reap(lambda p: p == dead.id, now=0.0) == []
    assert await leader.members.reap(lambda p: p == dead.id, now=REMOVE_AFTER - 1) == []
    assert await leader.members.reap(lambda p: p == dead.id, now=REMOVE_AFTER) == [dead.id]
    config = leader.groups.config(CHUNK)
    assert node_id(dead.id) not in config.members
    assert len(config.voters) == 1  # two holders: one voter and one learner, never two voters
    await write(leader, b"after")


async def test_peers_joining_at_once_all_end_up_members(world: World) -> None:
    """Each change is computed from the members after the one before: two joins
    computed side by side would take each other out again, and again."""
    _, leader = await group(world)
    newcomers = [await world.add(kind=Writer) for _ in range(3)]
    before = leader.groups.applied(CHUNK)
    await asyncio.gather(*(n.members.join(CHUNK, via=leader.id) for n in newcomers))
    config = leader.groups.config(CHUNK)
    assert {node_id(n.id) for n in newcomers} <= config.members
    assert len(config.voters) == 3  # the founders; the newcomers learn
    assert leader.groups.applied(CHUNK) - before <= 2 * len(newcomers)  # no churn
    for node in newcomers:
        assert value(node) == b"0"


async def removed_learner(world: World) -> tuple[Writer, Writer]:
    """A learner the leader removed as dead for `REMOVE_AFTER` (it was cut off) while
    it still knows that leader, and a commit it missed; (the learner, the leader)."""
    _, leader = await group(world)
    learner = await world.add(kind=Writer)
    assert isinstance(learner, Writer)
    await learner.members.join(CHUNK, via=leader.id)
    assert node_id(learner.id) in leader.groups.config(CHUNK).learners
    assert await leader.members.reap(lambda p: p == learner.id, now=0.0) == []
    assert await leader.members.reap(lambda p: p == learner.id, now=REMOVE_AFTER) == [learner.id]
    assert node_id(learner.id) not in leader.groups.config(CHUNK).members
    assert learner.groups.leader(CHUNK) == leader.id  # nothing told it
    await write(leader, b"while away")
    return learner, leader


def everyone(peer: PeerId) -> bool:
    return True


async def test_a_removed_learner_that_hears_nothing_asks_to_join_again(
    world: World, monkeypatch: pytest.MonkeyPatch
) -> None:
    learner, leader = await removed_learner(world)
    assert not learner.groups.quiet(CHUNK)  # it expects heartbeats
    monkeypatch.setattr(group_members, "STUCK_AFTER", 0.0)  # silent long enough already
    assert await learner.members.rejoin_stuck(everyone, now=1.0) == [CHUNK]
    assert node_id(learner.id) in leader.groups.config(CHUNK).learners
    await learner.wait(lambda: value(learner) == b"while away")


async def test_a_peer_that_stood_still_asks_every_group_again(world: World) -> None:
    learner, leader = await removed_learner(world)
    assert await learner.members.rejoin_stuck(everyone, now=0.0) == []  # heard it lately
    assert await learner.members.rejoin_stuck(everyone, now=REMOVE_AFTER) == [CHUNK]
    assert node_id(learner.id) in leader.groups.config(CHUNK).learners
    await learner.wait(lambda: value(learner) == b"while away")


async def test_a_member_that_hears_its_leader_asks_nothing(world: World) -> None:
    nodes, leader = await group(world)
    follower = next(n for n in nodes if n is not leader)
    for now in (0.0, 10.0, 20.0):
        assert await follower.members.rejoin_stuck(everyone, now=now) == []
    assert await follower.members.rejoin_stuck(everyone, now=20.0 + REMOVE_AFTER) == []
    assert node_id(follower.id) in leader.groups.config(CHUNK).voters  # asked, still one
