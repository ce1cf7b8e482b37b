"""Raft groups over real sockets (DESIGN §13): three peers on 127.0.0.1 share chunk
groups, persist them in real SQLite stores, elect, replicate, fail over and restart.

Each peer's apply hook records the entries it applies, so the tests compare what
every peer applied (one history per chunk) and wait for exactly the event they need.
"""

from __future__ import annotations

import asyncio
import sqlite3

import pytest

from mapapi.core import codec
from mapapi.core.change import Change, Op
from mapapi.core.clock import LamportClock
from mapapi.core.errors import ConflictError, NoQuorum, NotChunkLeader, RequestTimeout
from mapapi.core.ids import ChunkId, CommitId, ItemId
from mapapi.core.proposal import Proposal
from mapapi.core.transaction import Transaction
from mapapi.swarm.apply import Outcome
from mapapi.swarm.chain_watch import ChainWatch
from mapapi.swarm.group_members import change_members
from mapapi.swarm.log_commit import LogCommits
from tests.swarm.raft_world import (
    OPAQUE,
    Ledger,
    Node,
    World,
    Writer,
    founded,
    leader_of,
    propose_all,
)
from tests.swarm.raft_world import world as world  # the fixture

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
    while True:  # a leader just elected may step down again on a loaded machine
        successor = await leader_of(survivors, CHUNK)
        try:
            await propose_all(successor, CHUNK, [b"after"])
            break
        except NotChunkLeader:  # not appended: ask the next leader
            continue
    for node in survivors:
        await node.wait(lambda node=node: node.applied.get(CHUNK, [])[-1:] == [b"after"])
        assert node.applied[CHUNK] == [b"before", b"after"]


async def test_a_minority_cannot_commit(world: World) -> None:
    nodes = await founded(world, [CHUNK])
    leader = await leader_of(nodes, CHUNK)
    gone = [n for n in nodes if n is not leader]
    for node in gone:
        await node.stop()
        world.nodes.remove(node)
    # CheckQuorum deposes the leader once it hears from no majority; until then its
    # proposal cannot commit either: one way or the other, nothing is acknowledged.
    with pytest.raises((RequestTimeout, NotChunkLeader)) as caught:
        await leader.groups.propose(CHUNK, b"lost", timeout=0.05)
    assert b"lost" not in leader.applied.get(CHUNK, [])
    if isinstance(caught.value, RequestTimeout) and "no quorum" in str(caught.value):
        # still the leader when it gave up: it says who did not answer
        assert "1 of 3 voters" in str(caught.value)
        assert all(n.id.short in str(caught.value) for n in gone)


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
        node.groups.mail.frames_sent = node.groups.mail.messages_sent = 0
    await nodes[0].wait(lambda: nodes[0].groups.mail.frames_sent >= 20)  # heartbeats flow
    # Every node leads some of the 20 groups and follows the rest: each frame carries
    # the heartbeats (or their answers) of several groups, not one frame per group.
    for node in nodes:
        assert node.groups.mail.messages_sent >= 3 * node.groups.mail.frames_sent


# -- commits through the log: paper Algorithm 1 on one chunk's group -------------------
COUNTER = ItemId.new()
WRITERS, INCREMENTS, A0 = 4, 10, 100


async def counter_group(world: World, kind: type[Node]) -> list[Node]:
    """Three peers of `kind` founding the group of a counters chunk."""
    nodes = [await world.add(kind=kind) for _ in range(3)]
    for node in nodes:
        node.store.add_table("counters", OPAQUE)
        node.store.add_chunk(CHUNK, "counters")
        node.groups.found(CHUNK, [n.id for n in nodes])
    return nodes


async def increment(leader: Node, clock: LamportClock) -> int:
    """One optimistic increment, retried on conflict; returns how many attempts it took."""
    for attempt in range(1, 100):
        begin = leader.store.raft_time(CHUNK)
        value = int(leader.store.read(COUNTER, begin).data)  # type: ignore[union-attr]
        change = Change(Op.UPDATE, "counters", COUNTER, CHUNK, str(value + 1).encode())
        proposal = Proposal(
            CommitId.new(), clock.tick(), leader.id, "w", "", "+1", begin, "snapshot", (change,)
        )
        applied = await leader.groups.propose(CHUNK, codec.encode_entry(proposal))
        outcome = applied.result
        assert isinstance(outcome, Outcome)
        if outcome.committed:
            return attempt
    raise AssertionError("an increment never committed")


async def test_algorithm_1_through_the_log_ends_at_a0_plus_p_times_n(world: World) -> None:
    nodes = await counter_group(world, Ledger)
    leader = await leader_of(nodes, CHUNK)
    clock = LamportClock()
    first = Change(Op.INSERT, "counters", COUNTER, CHUNK, str(A0).encode())
    start = Proposal(
        CommitId.new(), clock.tick(), leader.id, "w", "", "a0", 0, "snapshot", (first,)
    )
    await leader.groups.propose(CHUNK, codec.encode_entry(start))

    async def writer() -> int:
        return sum([await increment(leader, clock) for _ in range(INCREMENTS)])

    attempts = await asyncio.gather(*(writer() for _ in range(WRITERS)))
    assert sum(attempts) > WRITERS * INCREMENTS  # the writers did race
    commits = 1 + WRITERS * INCREMENTS
    for node in nodes:
        await node.wait(lambda node=node: len(node.store.chunk_commits(CHUNK)) == commits)
    values = {int(n.store.latest([COUNTER])[COUNTER].data) for n in nodes}
    assert values == {A0 + WRITERS * INCREMENTS}
    histories = {tuple(c.id for c in n.store.chunk_commits(CHUNK)) for n in nodes}
    assert len(histories) == 1  # one history on every holder


# -- holders come and go through the log ------------------------------------------------
async def test_a_second_holder_is_a_learner_that_catches_up(world: World) -> None:
    first = await world.add()
    first.groups.found(CHUNK, [first.id])
    await propose_all(first, CHUNK, [b"a", b"b"])
    second = await world.add()
    await second.groups.join(CHUNK)
    config = await change_members(first.groups, CHUNK, [first.id, second.id])
    assert (len(config.voters), len(config.learners)) == (1, 1)  # never two voters
    await propose_all(first, CHUNK, [b"c"])  # the learner never holds a commit up
    await second.wait(lambda: second.applied.get(CHUNK) == [b"a", b"b", b"c"])


async def test_a_dead_voter_is_removed_and_a_learner_promoted(world: World) -> None:
    nodes = await founded(world, [CHUNK])
    leader = await leader_of(nodes, CHUNK)
    fourth = await world.add()
    await fourth.groups.join(CHUNK)
    config = await change_members(leader.groups, CHUNK, [*(n.id for n in nodes), fourth.id])
    assert (len(config.voters), len(config.learners)) == (3, 1)
    dead = next(n for n in nodes if n is not leader)
    await dead.stop()
    world.nodes.remove(dead)
    living = [n.id for n in world.nodes]
    config = await change_members(leader.groups, CHUNK, living)
    assert len(config.voters) == 3
    assert not config.learners
    await propose_all(leader, CHUNK, [b"after"])
    await fourth.wait(lambda: fourth.applied.get(CHUNK, [])[-1:] == [b"after"])


async def writers(world: World) -> tuple[list[Writer], Writer]:
    nodes = await counter_group(world, Writer)
    leader = await leader_of(nodes, CHUNK)
    for node in nodes:
        await node.wait(lambda node=node: node.groups.leader(CHUNK) == leader.id)
    return nodes, leader  # type: ignore[return-value]


def tx_of(node: Writer, data: bytes, op: Op = Op.UPDATE) -> Transaction:
    tx = Transaction(node, node.store.raft_time(CHUNK), node.id)
    tx.stage(Change(op, "counters", COUNTER, CHUNK, data))
    return tx


async def test_a_followers_transaction_commits_through_the_leader(world: World) -> None:
    nodes, leader = await writers(world)
    follower = next(n for n in nodes if n is not leader)
    record = await tx_of(follower, b"1", Op.INSERT).commit("from a follower")
    assert record is not None
    for node in nodes:
        await node.wait(lambda node=node: node.store.commit_record(record.id) == record)


async def test_a_conflict_reaches_a_follower_mergeable(world: World) -> None:
    nodes, leader = await writers(world)
    first, second = (n for n in nodes if n is not leader)
    await tx_of(first, b"0", Op.INSERT).commit("a0")
    await second.wait(lambda: second.store.latest([COUNTER]) != {})
    ours, theirs = tx_of(first, b"1"), tx_of(second, b"2")
    await ours.commit("first")
    with pytest.raises(ConflictError) as caught:
        await theirs.commit("second")
    assert [c.item_id for c in caught.value.conflicts] == [COUNTER]
    merged = caught.value.merge()  # the transaction lives here: it merges here
    merged.stage(Change(Op.UPDATE, "counters", COUNTER, CHUNK, b"3"))
    assert await merged.commit("merged") is not None


async def test_a_conflict_the_leader_sees_already_takes_no_round_of_the_log(
    world: World,
) -> None:
    """A stale transaction, from a follower or the leader itself, is answered its
    conflict by the leader's replica at once: its proposal is never appended."""
    nodes, leader = await writers(world)
    first, second = (n for n in nodes if n is not leader)
    await tx_of(first, b"0", Op.INSERT).commit("a0")
    await second.wait(lambda: second.store.latest([COUNTER]) != {})
    await leader.wait(lambda: leader.store.latest([COUNTER]) != {})
    stale = [tx_of(second, b"2"), tx_of(leader, b"3")]
    await tx_of(first, b"1").commit("first")  # answered once the leader applied it
    log = leader.groups._group(CHUNK).node.log  # the core's log, as the leader holds it
    last = log.last_index

    for tx in stale:
        with pytest.raises(ConflictError) as caught:
            await tx.commit("stale")
        assert [c.item_id for c in caught.value.conflicts] == [COUNTER]
    assert log.last_index == last


async def test_a_follower_catches_up_before_a_fresh_read(world: World) -> None:
    nodes = await founded(world, [CHUNK])
    leader = await leader_of(nodes, CHUNK)
    follower = next(n for n in nodes if n is not leader)
    await follower.wait(lambda: follower.groups.leader(CHUNK) == leader.id)
    await propose_all(leader, CHUNK, [b"fresh"])
    index = await follower.groups.catch_up(CHUNK)
    assert follower.groups.applied(CHUNK) >= index
    assert follower.applied[CHUNK] == [b"fresh"]  # no waiting on our side: catch_up did


# -- holders compare their histories ----------------------------------------------------
async def test_a_replica_whose_history_differs_says_so(world: World) -> None:
    nodes = await counter_group(world, Ledger)
    leader = await leader_of(nodes, CHUNK)
    clock = LamportClock()
    first = Change(Op.INSERT, "counters", COUNTER, CHUNK, b"1")
    start = Proposal(
        CommitId.new(), clock.tick(), leader.id, "w", "", "a0", 0, "snapshot", (first,)
    )
    await leader.groups.propose(CHUNK, codec.encode_entry(start))
    healthy, damaged = (n for n in nodes if n is not leader)
    for node in (healthy, damaged):
        await node.wait(lambda node=node: node.store.chain_length(CHUNK) == 1)
    con = sqlite3.connect(damaged.path)  # another history, as a rolled-back store would hold
    con.execute("UPDATE raft_chain SET link = ? WHERE seq = 1", (b"\x01" * 32,))
    con.commit()
    con.close()
    watches = {  # the Raft groups say what to compare: a leader's chunks, with their members
        n.id: ChainWatch(
            n.store, n.rpc, world.addresses.__getitem__, n.groups.led, n.groups.members
        )
        for n in nodes
    }
    await watches[leader.id].compare()
    assert "another history" in watches[damaged.id].diverged[CHUNK]
    assert [d.peer for d in leader.store.divergences()] == [damaged.id]  # both sides see it
    assert watches[healthy.id].diverged == {}


async def test_a_member_without_a_configuration_does_not_claim_no_quorum(world: World) -> None:
    """A group joined and not caught up (after a restart, say) knows no voters: a
    read fails as it did (no leader), not with "no quorum: 0 of 0 voters"."""
    node = await world.add()
    node.store.add_table("t", OPAQUE)
    node.store.add_chunk(CHUNK, "t")
    await node.groups.join(CHUNK)
    down = LogCommits(  # every peer looks down to it
        node.groups, node.rpc, world.addresses.__getitem__, LamportClock(), answers=lambda p: False
    )
    with pytest.raises(NotChunkLeader) as caught:
        await down.caught_up(CHUNK, timeout=0.05)
    assert not isinstance(caught.value, NoQuorum)
