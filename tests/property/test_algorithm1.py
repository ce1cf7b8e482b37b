"""Paper Algorithm 1: P threads each commit N increments of one counter, retrying on conflict.

No increment may be lost or doubled: the final value is exactly a0 + P*N and the
log holds exactly the insert plus one commit per increment (DESIGN §5, §12).
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from threading import Barrier
from typing import Any

import pytest

from mapapi import ConflictError, ItemId, MapError, Peer, Repository
from mapapi._pb.mapapi.v1.types_pb2 import Counter
from mapapi.sync import Blocking, open_peer, wrap

P, N, A0 = 4, 50, 7
TABLE = "counters"
TIMEOUT = 60.0


def setup_counter(peer: Blocking) -> ItemId:
    """Create the table, a chunk and the counter at A0 (one commit)."""
    peer.create_table(TABLE, Counter)
    chunk = peer.create_chunk(TABLE)
    tx = peer.begin()
    item_id: ItemId = tx.insert(TABLE, Counter(name="a", value=A0), chunk)
    assert tx.commit("insert a") is not None
    return item_id


def increment(peer: Blocking, item_id: ItemId) -> int:
    """One increment, retried until it commits; returns the number of conflicts."""
    conflicts = 0
    while True:
        tx = peer.begin()
        counter: Any = tx.get(TABLE, item_id)
        tx.update(TABLE, item_id, Counter(name=counter.name, value=counter.value + 1))
        try:
            tx.commit("increment")
        except MapError as err:
            if not err.retriable:  # conflicts and lock timeouts retry; anything else fails
                raise
            conflicts += isinstance(err, ConflictError)
            continue
        return conflicts


def run_threads(worker: Callable[[int], int]) -> int:
    """Run `worker(index)` in P threads at once; re-raise their errors; total conflicts."""
    with ThreadPoolExecutor(max_workers=P) as pool:
        futures = [pool.submit(worker, index) for index in range(P)]
        return sum(f.result(timeout=TIMEOUT) for f in futures)


def check_final(peer: Blocking, item_id: ItemId) -> None:
    tx = peer.begin()
    counter: Any = tx.get(TABLE, item_id)
    assert counter.value == A0 + P * N
    assert len(peer.log()) == 1 + P * N
    # Every increment saw the value before it: the history is A0, A0+1, ..., A0+P*N.
    values = [Counter.FromString(r.data).value for r in peer.history(item_id)]
    assert values == list(range(A0, A0 + P * N + 1))


@pytest.mark.parametrize("store", ["memory", "sqlite"])
def test_threads_sharing_one_peer(store: str, make_repo: Callable[..., Repository]) -> None:
    """(a) P threads share one peer through the blocking facade."""
    peer = wrap(Peer.in_memory()) if store == "memory" else open_peer(make_repo().root)
    with peer:
        item_id = setup_counter(peer)
        start = Barrier(P)

        def worker(_: int) -> int:
            start.wait(timeout=TIMEOUT)
            return sum(increment(peer, item_id) for _ in range(N))

        run_threads(worker)
        check_final(peer, item_id)


def test_threads_with_own_peers_on_one_repo(make_repo: Callable[..., Repository]) -> None:
    """(b) P threads each open their own peer on one SQLite repository file."""
    root: Path = make_repo().root
    with open_peer(root) as first:
        item_id = setup_counter(first)
    start = Barrier(P)

    def worker(_: int) -> int:
        with open_peer(root) as peer:
            start.wait(timeout=TIMEOUT)
            return sum(increment(peer, item_id) for _ in range(N))

    run_threads(worker)
    with open_peer(root) as peer:
        check_final(peer, item_id)
