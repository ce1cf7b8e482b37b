"""A chunk leader validates a proposal against its replica plus the entries in
flight (issue 13 §3, `swarm/in_flight.py`): the loser of a race on one item learns
its conflict once the winner applied, without a round of the log of its own."""

from __future__ import annotations

import asyncio

import pytest

from mapapi.core.change import Change, Op
from mapapi.core.errors import ConflictError
from mapapi.core.ids import ChunkId, ItemId
from mapapi.core.transaction import Transaction
from mapapi.swarm.in_flight import InFlight
from tests.swarm.raft_world import World, Writer, item_group
from tests.swarm.raft_world import world as world  # the fixture

CHUNK = ChunkId.new()
ITEM = ItemId.new()
RACERS = 4


def update(writer: Writer, value: bytes) -> Transaction:
    """A transaction begun at the writer's chunk clock that sets ITEM to `value`."""
    tx = Transaction(writer, writer.store.raft_time(CHUNK), writer.id)
    tx.stage(Change(Op.UPDATE, "t", ITEM, CHUNK, value))
    return tx


@pytest.mark.parametrize("at", ["leader", "follower"])
async def test_racers_on_one_item_cost_one_entry_of_the_log(world: World, at: str) -> None:
    follower, leader = await item_group(world, CHUNK, ITEM)
    writer = leader if at == "leader" else follower
    before = leader.groups.applied(CHUNK)
    racers = [update(writer, str(n).encode()) for n in range(RACERS)]
    results = await asyncio.gather(
        *(tx.commit(f"racer {n}") for n, tx in enumerate(racers)), return_exceptions=True
    )
    won = [r for r in results if not isinstance(r, BaseException)]
    lost = [r for r in results if isinstance(r, BaseException)]
    assert len(won) == 1
    assert all(isinstance(e, ConflictError) for e in lost), lost
    assert leader.groups.applied(CHUNK) == before + 1  # the winner's entry alone
    assert not leader.commits.in_flight  # nothing left held


async def test_a_waiter_goes_on_however_the_round_ahead_ended() -> None:
    flight = InFlight()
    round_ahead = flight.holding(CHUNK, [ITEM])
    round_ahead.__enter__()
    waiting = asyncio.ensure_future(flight.clear_of(CHUNK, [ITEM], timeout=10.0))
    await asyncio.sleep(0)  # sync-ok: one turn, in which the waiter finds ITEM held
    assert not waiting.done()
    failure = RuntimeError("the round ahead failed")
    assert not round_ahead.__exit__(RuntimeError, failure, None)  # the failure goes on up
    await waiting
    assert not flight


async def test_a_waiter_stops_waiting_at_its_deadline() -> None:
    flight = InFlight()
    with flight.holding(CHUNK, [ITEM]):
        await flight.clear_of(CHUNK, [ITEM], timeout=0.01)  # returns: the log decides
        await flight.clear_of(CHUNK, [ItemId.new()], timeout=10.0)  # another item: no wait
        await flight.clear_of(ChunkId.new(), [ITEM], timeout=10.0)  # another chunk: no wait
