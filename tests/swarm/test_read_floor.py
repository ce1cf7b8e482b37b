"""Views that read ahead of a chunk's clock (DESIGN §13): a reader whose Lamport time
runs ahead of a chunk closes the chunk's log at its begin time (`LogCommits.read_at`),
so a commit that lands afterwards, from a writer whose clock is far behind, is still
stamped past the view and found as a conflict, and the view's reads never change.
"""

from __future__ import annotations

import pytest

from mapapi.core.change import Change, Op
from mapapi.core.errors import ConflictError
from mapapi.core.ids import ChunkId, ItemId
from mapapi.core.transaction import Transaction
from tests.swarm.raft_world import OPAQUE, World, Writer, leader_of
from tests.swarm.raft_world import world as world  # the fixture

CHUNK = ChunkId.new()
ITEM = ItemId.new()
AHEAD = 1_000  # the reader's Lamport time, far past the chunk's clock


async def group(world: World) -> tuple[Writer, Writer]:
    """Three writers founding the chunk with ITEM in it; (a follower, the leader)."""
    nodes = [await world.add(kind=Writer) for _ in range(3)]
    for node in nodes:
        node.store.add_table("t", OPAQUE)
        node.store.add_chunk(CHUNK, "t")
        node.groups.found(CHUNK, [n.id for n in nodes])
    leader = await leader_of(nodes, CHUNK)  # type: ignore[arg-type]
    first = Transaction(leader, 0, leader.id)
    first.stage(Change(Op.INSERT, "t", ITEM, CHUNK, b"0"))
    await first.commit("0")
    follower = next(n for n in nodes if n is not leader)
    await follower.wait(lambda: follower.groups.leader(CHUNK) == leader.id)
    await follower.wait(lambda: follower.store.latest([ITEM]) != {})
    return follower, leader  # type: ignore[return-value]


async def test_a_write_after_a_view_closed_the_log_is_its_conflict(world: World) -> None:
    reader, writer = await group(world)
    await reader.commits.read_at(CHUNK, AHEAD)
    assert reader.store.raft_time(CHUNK) >= AHEAD
    seen = reader.store.read(ITEM, AHEAD)
    theirs = Transaction(writer, writer.store.raft_time(CHUNK), writer.id)
    theirs.stage(Change(Op.UPDATE, "t", ITEM, CHUNK, b"theirs"))
    landed = await theirs.commit("after the view began")  # the writer's clock is far behind
    assert landed is not None
    assert landed.time > AHEAD
    await reader.wait(lambda: reader.store.latest([ITEM])[ITEM].data == b"theirs")
    assert reader.store.read(ITEM, AHEAD) == seen  # the view reads what it read before
    ours = Transaction(reader, AHEAD, reader.id)
    ours.stage(Change(Op.UPDATE, "t", ITEM, CHUNK, b"ours"))
    with pytest.raises(ConflictError):
        await ours.commit("from the view")


async def test_a_clock_already_past_the_view_costs_no_floor(world: World) -> None:
    reader, _ = await group(world)
    applied = reader.groups.applied(CHUNK)
    await reader.commits.read_at(CHUNK, 1)
    assert reader.groups.applied(CHUNK) == applied  # no entry was added to the log
