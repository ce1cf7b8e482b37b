"""Snapshots of a chunk's state through its Raft group, over real sockets (DESIGN §13):
a holder that joins after the log was compacted, or a group founded over a chunk
with a history, catches up from the leader's snapshot and then follows the log.
"""

from __future__ import annotations

from mapapi.core.change import Change, Op
from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, CommitId, ItemId
from mapapi.core.transaction import Transaction
from mapapi.swarm.group_members import change_members
from tests.swarm.raft_world import OPAQUE, World, Writer, founding_writers
from tests.swarm.raft_world import world as world  # the fixture

CHUNK = ChunkId.new()
COUNTER = ItemId.new()


async def increment(node: Writer, times: int) -> None:
    for _ in range(times):
        begin = node.store.raft_time(CHUNK)
        now = node.store.read(COUNTER, begin)
        tx = Transaction(node, begin, node.id)
        op = Op.INSERT if now is None else Op.UPDATE
        value = 0 if now is None else int(now.data) + 1
        tx.stage(Change(op, "counters", COUNTER, CHUNK, str(value).encode()))
        await tx.commit("+1")


async def compacting_group(world: World) -> tuple[list[Writer], Writer]:
    """Three writers founding CHUNK's group, whose logs compact every 5 entries,
    and its leader."""
    world.compact_after = 5
    return await founding_writers(world, CHUNK, "counters")


def same_replica(a: Writer, b: Writer) -> bool:
    """Both hold the same history, clock and hash chain of the chunk."""
    return (
        [c.id for c in a.store.chunk_commits(CHUNK)] == [c.id for c in b.store.chunk_commits(CHUNK)]
        and a.store.raft_time(CHUNK) == b.store.raft_time(CHUNK)
        and a.store.chain_links(CHUNK) == b.store.chain_links(CHUNK)
    )


async def test_a_holder_joining_after_compaction_catches_up_from_a_snapshot(
    world: World,
) -> None:
    nodes, leader = await compacting_group(world)
    await increment(leader, 12)
    kept = leader.store.raft_load(CHUNK)
    assert kept is not None
    assert kept.snap_index > 1  # the log before it is gone: only a snapshot can catch up
    late = await world.add(kind=Writer)
    await late.groups.join(CHUNK)
    config = await change_members(leader.groups, CHUNK, [*(n.id for n in nodes), late.id])
    assert len(config.learners) == 1
    await late.wait(lambda: same_replica(late, leader))  # type: ignore[arg-type]
    assert late.store.latest([COUNTER])[COUNTER].data == b"11"
    await increment(leader, 1)  # type: ignore[arg-type]
    await late.wait(lambda: late.store.latest([COUNTER])[COUNTER].data == b"12")


async def test_a_chunk_with_a_history_hands_it_to_every_holder_that_joins(
    world: World,
) -> None:
    first = await world.add(kind=Writer)
    store = first.store
    store.add_table("counters", OPAQUE)
    store.add_chunk(CHUNK, "counters")
    for time in (1, 2, 3):  # committed alone, before the chunk had a group
        record = CommitRecord(CommitId.new(), time, first.id, f"v{time}", (CHUNK,))
        revision = Revision(
            COUNTER, "counters", CHUNK, str(time).encode(), 1, time, False, first.id, record.id
        )
        store.apply_commit(record, [revision])
    first.groups.found(CHUNK, [first.id])
    await first.wait(lambda: first.groups.is_leader(CHUNK))
    second = await world.add(kind=Writer)
    await second.groups.join(CHUNK)
    await change_members(first.groups, CHUNK, [first.id, second.id])
    await second.wait(lambda: same_replica(second, first))
    assert len(second.store.chunk_commits(CHUNK)) == 3
    await second.wait(lambda: second.groups.leader(CHUNK) == first.id)
    await increment(second, 1)  # a learner's commit goes through the leader
    for node in (first, second):
        await node.wait(lambda n=node: n.store.latest([COUNTER])[COUNTER].data == b"4")
    assert same_replica(first, second)
