"""The world of the two-chunk transaction simulation (`mapbench.sim_tx`): the bank
in two chunks, the faults drawn from a seed, and the end-of-run checks of every store.
"""

from __future__ import annotations

import random
from dataclasses import dataclass

from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId
from mapapi.store.memory import MemoryStore
from mapapi.swarm.chain_check import check_chain
from mapbench.sim_world import Violation

TABLE = "bank"
A = ChunkId(f"{0xC << 124 | 1:032x}")
B = ChunkId(f"{0xC << 124 | 2:032x}")
ACCOUNTS = {ItemId(f"{0xA << 124 | i:032x}"): chunk for i, chunk in enumerate([A, A, A, B, B, B])}
BALANCE, AMOUNT = 100, 30
TOTAL = BALANCE * len(ACCOUNTS)
GENESIS = CommitId(f"{0xE << 124:032x}")


@dataclass
class TxFaults:
    """How hostile the run is."""

    lost: float = 0.03  # a proposal never reaches the log
    answer_lost: float = 0.03  # it is appended, but its proposer never hears back
    max_delay: int = 8  # time units a proposal travels
    lag: float = 0.3  # chance a replica skips a turn applying a log
    crash_every: int = 150  # mean time units between crashes

    @classmethod
    def draw(cls, rng: random.Random) -> TxFaults:
        """A world drawn from a seed: calm to hostile."""
        return cls(
            rng.choice([0.0, 0.03, 0.1]),
            rng.choice([0.0, 0.03, 0.1]),
            rng.choice([2, 8, 20]),
            rng.choice([0.1, 0.3, 0.6]),
            rng.choice([80, 150, 10**9]),
        )


@dataclass
class Txn:
    """One client transaction and how it ended, as its writer learnt it."""

    cid: CommitId
    chunks: tuple[ChunkId, ...]
    status: str = "pending"  # acked, aborted, unknown


def genesis() -> MemoryStore:
    """A node's store: both chunks, every account at `BALANCE` in one genesis commit."""
    store = MemoryStore()
    store.add_table(TABLE, "google.protobuf.Struct")
    writer = PeerId(f"{0:032x}")
    revisions = [
        Revision(i, TABLE, c, str(BALANCE).encode(), 1, 1, False, writer, GENESIS)
        for i, c in ACCOUNTS.items()
    ]
    for chunk in (A, B):
        store.add_chunk(chunk, TABLE)
        store.raft_save(chunk, hard=(1, 0, 0))
        store.raft_applied(chunk, 0, 1)
    store.apply_commit(CommitRecord(GENESIS, 1, writer, "genesis", (A, B)), revisions)
    return store


def balances(store: MemoryStore, time: int) -> dict[ItemId, int]:
    """Every account at `time`; a `Violation` unless they add up to `TOTAL`."""
    read = {i: store.read(i, time) for i in ACCOUNTS}
    found = {i: int(r.data) for i, r in read.items() if r is not None}
    if sum(found.values()) != TOTAL or len(found) != len(ACCOUNTS):
        raise Violation(f"a read at time {time} saw a bank total of {sum(found.values())}")
    return found


def check_stores(stores: dict[int, MemoryStore], txns: list[Txn]) -> int:
    """The end-of-run rules (`mapbench.sim_tx`'s docstring) on every node's store;
    how many past times it read the whole bank at."""
    latest, reads = None, 0
    for n, store in stores.items():
        times = {c.time for chunk in (A, B) for c in store.chunk_commits(chunk)}
        for time in sorted(times):
            balances(store, time)
            reads += 1
        now = {i: r.data for i, r in store.latest(list(ACCOUNTS)).items()}
        if latest is not None and now != latest:
            raise Violation(f"node {n} ends with other balances than node 1")
        latest = now
        for chunk in (A, B):
            if problems := check_chain(store, chunk):
                raise Violation(f"node {n}: {problems[0]}")
        for txn in txns:
            _check_txn(n, store, txn)
    return reads


def _check_txn(n: int, store: MemoryStore, txn: Txn) -> None:
    record: CommitRecord | None = store.commit_record(txn.cid)
    if txn.status == "acked" and record is None:
        raise Violation(f"node {n}: acknowledged {txn.cid.short} is missing")
    if txn.status == "aborted" and record is not None:
        raise Violation(f"node {n}: {txn.cid.short}, reported aborted, is present")
    if record is not None:
        written: list[Revision] = store.commit_revisions(txn.cid)
        if {r.chunk_id for r in written} != set(txn.chunks):
            raise Violation(f"node {n}: {txn.cid.short} is only partly applied")
        if {r.update_time for r in written} != {record.time}:
            raise Violation(f"node {n}: {txn.cid.short} has more than one time")
