"""Bank transfers: serializable isolation keeps invariants that read several items.

Concurrent transfers between accounts, each thread with its own peer on one
SQLite repository, must conserve the total and never overdraw. And the classic
write skew: two transactions each read two accounts and debit a different one
under the constraint "sum >= 0"; snapshot isolation lets both commit (the
constraint breaks), serializable isolation refuses the second (DESIGN §5.4).
"""

from __future__ import annotations

import random
from collections.abc import Awaitable, Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from threading import Barrier
from typing import Any

import pytest

from mapapi import ConflictError, ItemId, Peer, Repository
from mapapi._pb.mapapi.v1.types_pb2 import Account
from mapapi.sync import Blocking, open_peer

TABLE = "accounts"
OWNERS = ["ann", "bob", "cid", "dee", "eve"]
OPENING = 100
THREADS, TRANSFERS = 4, 25
TIMEOUT = 60.0


def open_accounts(peer: Blocking) -> list[ItemId]:
    peer.create_table(TABLE, Account)
    chunk = peer.create_chunk(TABLE)
    tx = peer.begin()
    ids = [tx.insert(TABLE, Account(owner=o, balance=OPENING), chunk) for o in OWNERS]
    tx.commit("open accounts")
    return ids


def transfer(peer: Blocking, source: ItemId, target: ItemId, amount: int) -> tuple[bool, int]:
    """Move `amount` unless the source would go negative; (done, conflicts seen)."""
    conflicts = 0
    while True:
        tx = peer.begin(isolation="serializable")
        a: Any = tx.get(TABLE, source)
        b: Any = tx.get(TABLE, target)
        if a.balance < amount:
            tx.abort()
            return False, conflicts
        tx.update(TABLE, source, Account(owner=a.owner, balance=a.balance - amount))
        tx.update(TABLE, target, Account(owner=b.owner, balance=b.balance + amount))
        try:
            tx.commit(f"{a.owner} -> {b.owner}: {amount}")
        except ConflictError:
            conflicts += 1
            continue
        return True, conflicts


def balances_at(peer: Blocking, ids: list[ItemId], time: int | None = None) -> list[int]:
    tx = peer.begin(time)
    return [tx.get(TABLE, i).balance for i in ids]


def test_concurrent_transfers_conserve_money(make_repo: Callable[..., Repository]) -> None:
    root: Path = make_repo().root
    with open_peer(root) as bank:
        ids = open_accounts(bank)
    start = Barrier(THREADS)

    def teller(index: int) -> int:
        rng = random.Random(index)
        done = 0
        with open_peer(root) as peer:
            start.wait(timeout=TIMEOUT)
            for _ in range(TRANSFERS):
                source, target = rng.sample(ids, 2)
                ok, _ = transfer(peer, source, target, rng.randint(1, 60))
                done += ok
        return done

    with ThreadPoolExecutor(max_workers=THREADS) as pool:
        futures = [pool.submit(teller, i) for i in range(THREADS)]
        done = sum(f.result(timeout=TIMEOUT) for f in futures)

    with open_peer(root) as peer:
        final = balances_at(peer, ids)
        assert sum(final) == OPENING * len(OWNERS)
        assert min(final) >= 0
        commits = peer.log()
        assert len(commits) == 1 + done
        # Every committed state, not just the last, conserves money and overdraws no one.
        for record in commits:
            snapshot = balances_at(peer, ids, record.time)
            assert sum(snapshot) == OPENING * len(OWNERS), record
            assert min(snapshot) >= 0, record


@pytest.mark.parametrize("isolation", ["snapshot", "serializable"])
async def test_write_skew(isolation: str, make_peer: Callable[[], Awaitable[Peer]]) -> None:
    """Two interleaved transactions, each keeping x + y >= 0 in its own snapshot."""
    peer = await make_peer()
    await peer.create_table(TABLE, Account)
    chunk = await peer.create_chunk(TABLE)
    setup = peer.begin()
    x = setup.insert(TABLE, Account(owner="x", balance=50), chunk)
    y = setup.insert(TABLE, Account(owner="y", balance=50), chunk)
    await setup.commit()

    first = peer.begin(isolation=isolation)  # type: ignore[arg-type]
    second = peer.begin(isolation=isolation)  # type: ignore[arg-type]
    for tx, debited in ((first, x), (second, y)):
        a: Any = await tx.get(TABLE, x)
        b: Any = await tx.get(TABLE, y)
        assert a.balance + b.balance - 100 >= 0  # the debit is allowed in this snapshot
        old = a if debited == x else b
        tx.update(TABLE, debited, Account(owner=old.owner, balance=old.balance - 100))

    assert await first.commit("debit x") is not None
    if isolation == "snapshot":
        assert await second.commit("debit y") is not None  # write skew: disjoint write sets
    else:
        with pytest.raises(ConflictError) as caught:
            await second.commit("debit y")
        assert [c.item_id for c in caught.value.conflicts] == [x]
        assert caught.value.conflicts[0].ours is None  # a read, not a write, conflicted

    now = peer.begin()
    total = sum([(await now.get(TABLE, i)).balance for i in (x, y)])  # type: ignore[union-attr]
    if isolation == "snapshot":
        assert total == -100  # the constraint x + y >= 0 is violated
    else:
        assert total == 0
