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
from tests.swarm.raft_world import World, item_group
from tests.swarm.raft_world import world as world  # the fixture

CHUNK = ChunkId.new()
ITEM = ItemId.new()
AHEAD = 1_000  # the reader's Lamport time, far past the chunk's clock


async def test_a_write_after_a_view_closed_the_log_is_its_conflict(world: World) -> None:
    reader, writer = await item_group(world, CHUNK, ITEM)
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
    reader, _ = await item_group(world, CHUNK, ITEM)
    applied = reader.groups.applied(CHUNK)
    await reader.commits.read_at(CHUNK, 1)
    assert reader.groups.applied(CHUNK) == applied  # no entry was added to the log
