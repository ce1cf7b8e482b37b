"""Transactions over two chunks through their Raft groups, over real sockets (DESIGN
§13): two-phase commit with prepares and decisions in the chunks' logs, concurrent
transfers that conserve the total, and transactions whose coordinator vanished,
settled from the logs by the chunks' leaders (`swarm/tx_recovery.py`).
"""

from __future__ import annotations

import asyncio

from mapapi.core.change import Change, Op
from mapapi.core.errors import ChunkBusy, ConflictError, ProposalLost
from mapapi.core.history import CommitRecord
from mapapi.core.ids import ChunkId, CommitId, ItemId
from mapapi.core.proposal import Proposal, TxDecision
from mapapi.core.transaction import Transaction
from mapapi.swarm.tx_recovery import TxRecovery
from tests.swarm.raft_world import OPAQUE, World, Writer, leader_of
from tests.swarm.raft_world import world as world  # the fixture

TABLE = "accounts"
A, B = sorted([ChunkId.new(), ChunkId.new()])
X, Y = ItemId.new(), ItemId.new()  # one account in each chunk
START = 100


async def bank(world: World) -> list[Writer]:
    """Three writers founding the groups of both chunks, every one knowing both leaders,
    and the two accounts opened by one transaction over both chunks."""
    nodes = [await world.add(kind=Writer) for _ in range(3)]
    for node in nodes:
        node.store.add_table(TABLE, OPAQUE)
        for chunk in (A, B):
            node.store.add_chunk(chunk, TABLE)
            node.groups.found(chunk, [n.id for n in nodes])
    for chunk in (A, B):
        leader = await leader_of(nodes, chunk)  # type: ignore[arg-type]
        for node in nodes:
            await node.wait(lambda n=node, c=chunk, lead=leader: n.groups.leader(c) == lead.id)
    opening = Transaction(nodes[0], 0, nodes[0].id)
    for item, chunk in ((X, A), (Y, B)):
        opening.stage(Change(Op.INSERT, TABLE, item, chunk, str(START).encode()))
    await opening.commit("open")
    for node in nodes:  # every replica shows the accounts before the tests read them
        await node.wait(lambda n=node: begin_time(n) > 0)
    return nodes  # type: ignore[return-value]


def begin_time(node: Writer) -> int:
    """A time at which this replica shows both chunks whole: past every commit it
    applied to either, and before any it may still apply (each chunk's later commits
    come after its clock; a prepared chunk's clock waits for the decision)."""
    return min(node.store.raft_time(A), node.store.raft_time(B))


def balances(node: Writer, time: int | None = None) -> tuple[int, int]:
    at = begin_time(node) if time is None else time
    x, y = (node.store.read(i, at) for i in (X, Y))
    assert x is not None
    assert y is not None
    return int(x.data), int(y.data)


async def transfer(node: Writer) -> CommitRecord:
    """Move 1 from X to Y, read at this replica's begin time; the commit."""
    begin = begin_time(node)
    x, y = balances(node, begin)
    tx = Transaction(node, begin, node.id)
    tx.stage(Change(Op.UPDATE, TABLE, X, A, str(x - 1).encode()))
    tx.stage(Change(Op.UPDATE, TABLE, Y, B, str(y + 1).encode()))
    record = await tx.commit("move 1")
    assert record is not None
    return record


def has_decided(node: Writer, cid: CommitId) -> bool:
    """Whether this replica applied a decision of the transaction on both chunks."""
    rows = [node.store.raft_tx(c, cid) for c in (A, B)]
    return all(r is not None and r.state != "prepared" for r in rows)


def settled(nodes: list[Writer]) -> bool:
    return all(not n.store.raft_tx_prepared(c) for n in nodes for c in (A, B))


async def test_a_transaction_over_two_chunks_commits_at_one_time_everywhere(
    world: World,
) -> None:
    nodes = await bank(world)
    record = await transfer(nodes[1])  # a follower of at least one chunk, maybe both
    assert record.chunks == (A, B)
    for node in nodes:
        await node.wait(lambda n=node: balances(n) == (START - 1, START + 1))
        written = node.store.commit_revisions(record.id)
        assert {r.item_id for r in written} == {X, Y}
        assert {r.update_time for r in written} == {record.time}  # one commit, one time
        assert node.store.commit_record(record.id) == record
    assert settled(nodes)


async def test_concurrent_transfers_conserve_the_total_and_lose_none(world: World) -> None:
    nodes = await bank(world)
    acked: list[CommitId] = []
    refused: list[Exception] = []
    per_writer = 6

    async def writer(node: Writer) -> None:
        done = 0
        while done < per_writer:
            try:
                record = await transfer(node)
            except (ConflictError, ChunkBusy, ProposalLost) as exc:
                refused.append(exc)
                await node.wait(lambda: True)  # let the other writers' commits land
                continue
            finally:
                x, y = balances(node)  # any replica, any time: never half a transfer
                assert x + y == 2 * START
            acked.append(record.id)
            done += 1

    await asyncio.gather(*(writer(n) for n in nodes))
    assert len(set(acked)) == 3 * per_writer
    assert refused  # the writers did race
    for node in nodes:
        await node.wait(lambda n=node: balances(n)[0] == START - len(acked))
        assert balances(node) == (START - len(acked), START + len(acked))
        for cid in acked:
            assert node.store.commit_record(cid) is not None
    assert settled(nodes)


def prepares(node: Writer) -> dict[ChunkId, Proposal]:
    """A transfer's prepares, as a coordinator would propose them."""
    tx = Transaction(node, begin_time(node), node.id)
    tx.stage(Change(Op.UPDATE, TABLE, X, A, b"0"))
    tx.stage(Change(Op.UPDATE, TABLE, Y, B, b"200"))
    cid = CommitId.new()
    return {c: Proposal.of(tx, c, "all to Y", 1, (A, B), cid) for c in (A, B)}


async def recovering(nodes: list[Writer]) -> list[TxRecovery]:
    made = [TxRecovery(n.commits, after=0.05) for n in nodes]
    for recovery in made:
        recovery.start(every=0.02)
    return made


async def test_prepares_left_by_a_vanished_coordinator_are_aborted(world: World) -> None:
    nodes = await bank(world)
    coordinator = nodes[2]
    left = prepares(coordinator)
    for chunk in (A, B):  # prepared everywhere, then the coordinator is gone
        assert (await coordinator.commits.propose(chunk, left[chunk])).prepared
    cid = left[A].commit_id
    recoveries = await recovering(nodes)
    try:
        for node in nodes:
            await node.wait(
                lambda n=node: has_decided(n, cid)
            )  # its prepares applied, then settled
            assert {node.store.raft_tx(c, cid).state for c in (A, B)} == {"aborted"}  # type: ignore[union-attr]
            assert balances(node) == (START, START)
        await transfer(nodes[0])  # the chunks take commits again
    finally:
        for recovery in recoveries:
            await recovery.close()


async def test_a_commit_decided_on_the_first_chunk_is_carried_to_the_others(
    world: World,
) -> None:
    nodes = await bank(world)
    coordinator = nodes[2]
    left = prepares(coordinator)
    times = [(await coordinator.commits.propose(c, left[c])).prepared for c in (A, B)]
    cid = left[A].commit_id
    decided = await coordinator.commits.propose(A, TxDecision(cid, True, max(times)))
    assert decided.record is not None  # committed on A; the coordinator dies before B
    recoveries = await recovering(nodes)
    try:
        for node in nodes:
            await node.wait(lambda n=node: has_decided(n, cid))
            assert balances(node) == (0, 200)
            assert node.store.raft_tx(B, cid).state == "committed"  # type: ignore[union-attr]
    finally:
        for recovery in recoveries:
            await recovery.close()
