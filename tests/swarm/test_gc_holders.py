"""`gc` across the holders of a chunk (issue 14 §4), over real sockets: each holder
compacts its own replica, at its own horizon; their chains stay equal and sound,
the group goes on committing, and a holder that joins from a compacted leader's
snapshot gets the same chain."""

from __future__ import annotations

from mapapi.swarm.chain_check import check_chain
from mapapi.swarm.group_members import change_members
from tests.swarm.raft_world import World, Writer
from tests.swarm.raft_world import world as world  # the fixture
from tests.swarm.test_groups_snapshot import CHUNK, COUNTER, compacting_group, increment


def chains(nodes: list[Writer]) -> list[object]:
    return [n.store.chain_links(CHUNK) for n in nodes]


async def test_holders_compact_apart_and_keep_one_chain(world: World) -> None:
    nodes, leader = await compacting_group(world)
    await increment(leader, 12)
    for node in nodes:  # every holder applied the twelve
        await node.wait(lambda n=node: len(n.store.history(COUNTER)) == 12)
    follower = next(n for n in nodes if n is not leader)

    snapped = leader.store.raft_load(CHUNK)
    assert snapped is not None
    assert leader.store.compact_history(leader.store.clock()).revisions == 11
    assert follower.store.compact_history(6).revisions == 5

    assert [len(n.store.history(COUNTER)) for n in (leader, follower)] == [1, 7]
    assert len({repr(c) for c in chains(nodes)}) == 1  # links never change
    for node in nodes:
        assert check_chain(node.store, CHUNK) == []
    written = 12
    while True:  # commit on until the leader's log compacts into a snapshot taken after gc
        await increment(leader, 1)
        written += 1
        kept = leader.store.raft_load(CHUNK)
        assert kept is not None
        if kept.snap_index > snapped.snap_index:
            break
        assert written < 30, "the leader's log never compacted again"
    newest = str(written - 1).encode()
    for node in nodes:
        await node.wait(lambda n=node: n.store.latest([COUNTER])[COUNTER].data == newest)
    assert len({repr(c) for c in chains(nodes)}) == 1
    for node in nodes:
        assert check_chain(node.store, CHUNK) == []

    late = await world.add(kind=Writer)  # the log before the snapshot is gone
    await late.groups.join(CHUNK)
    await change_members(leader.groups, CHUNK, [*(n.id for n in nodes), late.id])
    await late.wait(lambda: late.store.chain_links(CHUNK) == leader.store.chain_links(CHUNK))
    assert check_chain(late.store, CHUNK) == []
    assert late.store.chain_base(CHUNK) == leader.store.chain_base(CHUNK)
    assert len(late.store.chain_base(CHUNK)) == 11  # the links gc left bare, carried over
    assert late.store.latest([COUNTER])[COUNTER].data == newest
