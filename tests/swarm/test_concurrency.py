"""Concurrent writers on several peers: no increment lost, multi-chunk and
multi-table transactions, lock order, serializable isolation (paper Algorithm 1;
NetTableTest.Transactions; the bank invariant)."""

from __future__ import annotations

import asyncio
import random

import pytest

from mapapi import ChunkId, ConflictError, ItemId, NetworkError, Peer
from mapapi.core.transaction import Isolation
from tests.swarm.conftest import (
    ACCOUNTS,
    TABLE,
    Account,
    Counter,
    MakeSwarm,
    counter_chunk,
    increment,
    log_ids,
    share,
    value,
)


async def _same_everywhere(peers: list[Peer]) -> None:
    """Every peer holds the same commits (same ids, same order)."""
    for peer in peers[1:]:
        assert await log_ids(peer) == await log_ids(peers[0]), (
            f"{peer.name} differs from {peers[0].name}"
        )


class TestAlgorithm1:
    async def test_concurrent_increments_on_four_peers(self, swarm: MakeSwarm) -> None:
        """P peers x T tasks each commit N increments of one item, retrying on
        conflicts and lock timeouts: the final value is a0 + P*T*N everywhere."""
        p, t, n, a0 = 4, 3, 8, 7
        peers = await swarm(p)
        chunk, item = await counter_chunk(peers[0], a0)
        await share(chunk, peers[1:])
        start = asyncio.Event()

        async def worker(peer: Peer) -> int:
            await start.wait()
            return sum([await increment(peer, [(TABLE, item)]) for _ in range(n)])

        async with asyncio.timeout(40):
            tasks = [asyncio.create_task(worker(peer)) for peer in peers for _ in range(t)]
            start.set()
            await asyncio.gather(*tasks)
        for peer in peers:
            assert await value(peer, item) == a0 + p * t * n, peer.name
            assert len(await log_ids(peer)) == 1 + p * t * n
        await _same_everywhere(peers)
        values = [
            Counter.FromString(r.data).value for r in peers[-1].history(item)
        ]  # every increment is its own revision, none lost or doubled
        assert values == list(range(a0, a0 + p * t * n + 1))


class TestTwoChunksTwoTables:
    async def test_ab_and_b_end_at_20_and_10(self, swarm: MakeSwarm) -> None:
        """NetTableTest.Transactions: chunk "ab" in table 1 and chunk "b" in table 2;
        A increments ab (and inserts into chunk ab) 10 times, B increments ab and
        b together 10 times, concurrently."""
        root, a, b = await swarm(3)
        ab_chunk, ab = await counter_chunk(root, table="first", name="ab")
        b_chunk, b_item = await counter_chunk(root, table="second", name="b")
        await a.participate(ab_chunk)
        await share(ab_chunk, [b])
        await share(b_chunk, [b])
        rounds = 10

        async def peer_a() -> None:
            for _ in range(rounds):
                while True:
                    tx = a.begin()
                    current = await tx.get("first", ab)
                    assert current is not None
                    tx.update("first", ab, Counter(name="ab", value=current.value + 1))
                    tx.insert("first", Counter(name="extra", value=0), ab_chunk)
                    try:
                        await tx.commit("A: ab += 1, insert")
                    except (ConflictError, NetworkError):
                        continue
                    break

        async def peer_b() -> None:
            for _ in range(rounds):
                await increment(b, [("first", ab), ("second", b_item)], "B: ab += 1, b += 1")

        async with asyncio.timeout(30):
            await asyncio.gather(peer_a(), peer_b())
        for peer in (root, a, b):
            assert await value(peer, ab, table="first") == 2 * rounds, peer.name
            assert len(await peer.begin().items("first", ab_chunk)) == rounds + 1
        for peer in (root, b):
            assert await value(peer, b_item, table="second") == rounds, peer.name
        assert await log_ids(root) == await log_ids(b)
        assert b_chunk not in {c.id for c in a.chunks()}  # a never needed table 2
        joint = [c for c in root.log() if c.message.startswith("B:")]
        assert len(joint) == rounds
        assert all(set(c.chunks) == {ab_chunk, b_chunk} for c in joint)


class TestLockOrder:
    async def test_opposite_user_orders_never_deadlock(self, swarm: MakeSwarm) -> None:
        """Two peers update the same two chunks, in opposite orders, many times:
        locks are taken in ChunkId order, so no writer ever waits for a lock
        timeout (which is set far beyond the test's own deadline)."""
        x, y, z = await swarm(3)
        first, one = await counter_chunk(x, name="one")
        second, two = await counter_chunk(y, name="two")
        await share(first, [y, z])
        await share(second, [x, z])
        rounds = 15

        async def writer(peer: Peer, order: list[ItemId]) -> None:
            for _ in range(rounds):
                while True:
                    tx = peer.begin()
                    for item in order:
                        current = await tx.get(TABLE, item)
                        assert current is not None
                        tx.update(TABLE, item, Counter(name=current.name, value=current.value + 1))
                    try:
                        await tx.commit("both")
                    except ConflictError:
                        continue
                    break

        async with asyncio.timeout(20):
            await asyncio.gather(writer(x, [one, two]), writer(y, [two, one]))
        for peer in (x, y, z):
            assert await value(peer, one) == await value(peer, two) == 2 * rounds
        await _same_everywhere([x, y, z])


async def _open_accounts(
    peer: Peer, owners: list[str], balance: int
) -> tuple[ChunkId, list[ItemId]]:
    """A new chunk of accounts on `peer`."""
    if ACCOUNTS not in peer.store.tables():
        await peer.create_table(ACCOUNTS, Account)
    chunk = await peer.create_chunk(ACCOUNTS)
    tx = peer.begin()
    ids = [tx.insert(ACCOUNTS, Account(owner=o, balance=balance), chunk) for o in owners]
    await tx.commit(f"open {owners}")
    return chunk, ids


async def _balances(peer: Peer, ids: list[ItemId]) -> list[int]:
    """Each account as a view begun now on `peer` reads it: one view per account,
    since a view's first read catches its chunk up and moves the view's time to
    it, while a view that has read stays at its time for the next chunk (where a
    commit acknowledged a moment ago may be stamped later, by another clock)."""
    out = []
    for item in ids:
        account = await peer.begin().get(ACCOUNTS, item)
        assert account is not None
        out.append(int(account.balance))
    return out


class TestSerializable:
    async def test_transfers_between_chunks_of_different_peers_conserve_money(
        self, swarm: MakeSwarm
    ) -> None:
        peers = await swarm(3)
        opening = 100
        ids: list[ItemId] = []
        chunks: list[ChunkId] = []
        for index, peer in enumerate(peers):  # each peer opens accounts in its own chunk
            chunk, opened = await _open_accounts(peer, [f"p{index}a", f"p{index}b"], opening)
            chunks.append(chunk)
            ids += opened
        for chunk, peer in zip(chunks, peers, strict=True):  # and replicates the others'
            await share(chunk, [p for p in peers if p is not peer])
        rng = random.Random(3)

        async def teller(peer: Peer, seed: int) -> None:
            rng = random.Random(seed)
            for _ in range(6):
                source, target = rng.sample(ids, 2)
                amount = rng.randint(1, 80)
                while True:
                    tx = peer.begin(isolation="serializable")
                    a = await tx.get(ACCOUNTS, source)
                    b = await tx.get(ACCOUNTS, target)
                    assert a is not None
                    assert b is not None
                    if a.balance < amount:
                        tx.abort()
                        break
                    tx.update(ACCOUNTS, source, Account(owner=a.owner, balance=a.balance - amount))
                    tx.update(ACCOUNTS, target, Account(owner=b.owner, balance=b.balance + amount))
                    try:
                        await tx.commit(f"{a.owner} -> {b.owner}: {amount}")
                    except (ConflictError, NetworkError):
                        continue
                    break

        async with asyncio.timeout(40):
            await asyncio.gather(*(teller(p, rng.randrange(1 << 30)) for p in peers for _ in "ab"))
        for peer in peers:
            balances = await _balances(peer, ids)
            assert sum(balances) == opening * len(ids), peer.name
            assert min(balances) >= 0
        await _same_everywhere(peers)
        for chunk in chunks:  # every replica of a chunk holds the same history
            histories = {
                tuple(str(r.commit_id) for r in p.store.chunk_revisions(chunk)) for p in peers
            }
            assert len(histories) == 1

    @pytest.mark.parametrize("isolation", ["snapshot", "serializable"])
    async def test_write_skew_across_peers(self, swarm: MakeSwarm, isolation: Isolation) -> None:
        """x and y each read both accounts (in chunks created on different peers)
        and debit a different one under "a + b >= 0": serializable refuses the
        second commit; snapshot lets both through (the write skew)."""
        x, y = await swarm(2)
        chunk_a, [a] = await _open_accounts(x, ["a"], 50)
        chunk_b, [b] = await _open_accounts(y, ["b"], 50)
        await x.participate(chunk_b)
        await y.participate(chunk_a)
        tx_x = x.begin(isolation=isolation)
        tx_y = y.begin(isolation=isolation)
        for tx in (tx_x, tx_y):  # both read both accounts before either commits
            total = 0
            for item in (a, b):
                account = await tx.get(ACCOUNTS, item)
                assert account is not None
                total += account.balance
            assert total == 100
        tx_x.update(ACCOUNTS, a, Account(owner="a", balance=50 - 100))
        tx_y.update(ACCOUNTS, b, Account(owner="b", balance=50 - 100))
        await tx_x.commit("x takes 100 from a")
        if isolation == "snapshot":
            await tx_y.commit("y takes 100 from b")
            assert sum(await _balances(x, [a, b])) == sum(await _balances(y, [a, b])) == -100
            return
        with pytest.raises(ConflictError) as caught:
            await tx_y.commit("y takes 100 from b")
        [conflict] = caught.value.conflicts
        assert conflict.item_id == a
        assert conflict.ours is None  # a read, not a write
        assert sum(await _balances(y, [a, b])) == 0
        assert sum(await _balances(x, [a, b])) == 0
