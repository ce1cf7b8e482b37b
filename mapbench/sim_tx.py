"""A deterministic simulation of transactions over two chunks (two-phase commit, DESIGN §13).

The code under test is the real one: the coordinator (`swarm/two_phase.py`), every
holder's decision of prepares, decisions and one-chunk proposals (`swarm/apply_tx.py`
on a `MemoryStore` per node), and recovery's rule (ask the first chunk's log, then
follow it; `swarm/tx_recovery.py`). What is simulated is below them: each chunk's
Raft log is one ordered list of entries, as `mapbench.sim` proves a group keeps, and
from one seed the run draws when a proposal is lost before it is appended, when its
answer is lost after, how far each replica lags behind each log, and when nodes crash
(their coordinators and recoveries die, their stores survive) and restart.

Clients move money between six accounts, three in each chunk: within one chunk (one
proposal) or across both (two-phase commit), reading at a time at which their node's
replica shows both chunks whole. The checker fails the run (`Violation`) when:

- any read at such a time, or at any commit's time on any replica, sees a bank total
  other than the one the run started with (a transaction seen half applied);
- a transaction acknowledged as committed is missing, or one reported aborted is
  present, on any replica, or a multi-chunk commit has two times;
- after healing, a prepare stays undecided, replicas differ, or a hash chain breaks.
"""

from __future__ import annotations

import heapq
import random
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from mapapi.core import codec
from mapapi.core.change import Change, Op
from mapapi.core.ids import ChunkId, CommitId, PeerId
from mapapi.core.proposal import LogEntry, Proposal, TxDecision
from mapapi.swarm.apply import Outcome
from mapapi.swarm.apply_tx import applier
from mapapi.swarm.raft_types import Entry, EntryKind
from mapapi.swarm.two_phase import Answer, TwoPhase
from mapbench.sim_tx_world import (
    ACCOUNTS,
    AMOUNT,
    TABLE,
    A,
    B,
    TxFaults,
    Txn,
    balances,
    check_stores,
    genesis,
)
from mapbench.sim_world import Violation

TIMEOUT = 40
"""Time units after which a proposer that heard nothing gives up: an unknown outcome."""
BUSY_TRIES = 6
"""Proposals refused as busy are made again this many times before the writer gives up."""
SPACING = 12
"""Time units between two clients' starts, on average."""
RECOVER_AFTER = 80
"""Time units a prepare waits, as a chunk's leader saw it, before the leader settles it."""


@dataclass
class TxSim:
    """Nodes holding both chunks, clients, faults and the checker, from one seed."""

    seed: int
    nodes: int = 3
    ops: int = 40
    faults: TxFaults | None = None  # None: drawn from the seed

    def __post_init__(self) -> None:
        self.rng = random.Random(self.seed)
        self.world = self.faults or TxFaults.draw(self.rng)
        self.now = self._seq = self._ids = 0
        self._events: list[tuple[int, int, Callable[[], None]]] = []
        self.stores = {n: genesis() for n in range(1, self.nodes + 1)}
        self.logs: dict[ChunkId, list[bytes]] = {A: [], B: []}
        self.alive = dict.fromkeys(self.stores, True)
        self.epoch = dict.fromkeys(self.stores, 0)
        self.waiting: dict[tuple[int, ChunkId, int], tuple[int, Callable[[Any], None]]] = {}
        self.txns: list[Txn] = []
        self.seen: dict[tuple[ChunkId, CommitId], int] = {}
        self.settling: set[tuple[ChunkId, CommitId]] = set()
        self.settled = self.busy = self.reads = 0
        self.running = 0  # coordinators and recoveries not finished

    # -- the event loop -------------------------------------------------------------------
    def at(self, delay: int, action: Callable[[], None]) -> None:
        """Run `action` `delay` time units from now."""
        self._seq += 1
        heapq.heappush(self._events, (self.now + delay, self._seq, action))

    def run(self) -> None:
        """Clients and faults, then heal and settle; raises `Violation` on a broken rule."""
        try:
            for n in range(self.ops):
                self.at(5 + SPACING * n + self.rng.randrange(SPACING), self._client)
            self.at(1, self._apply_round)
            self.at(self.rng.randrange(self.world.crash_every), self._crash)
            self.at(1, self._recover_round)
            self._run_until(lambda: self.now > SPACING * (self.ops + 1))
            self.world.lost = self.world.answer_lost = self.world.lag = 0.0
            self.world.crash_every = 0
            for n in self.stores:
                self.alive[n] = True
            self._run_until(self._quiet, limit=self.now + 200 * RECOVER_AFTER)
            self.check()
        except Violation:
            raise
        except Exception as exc:
            raise Violation(f"{type(exc).__name__}: {exc}") from exc

    def _run_until(self, done: Callable[[], bool], limit: int | None = None) -> None:
        while not done():
            if not self._events or (limit is not None and self.now > limit):
                raise Violation(f"not settled at time {self.now}: {self._pending()}")
            self.now, _, action = heapq.heappop(self._events)
            action()

    def _quiet(self) -> bool:
        applied = all(self._applied(n, c) == len(self.logs[c]) for n in self.stores for c in (A, B))
        prepared = any(s.raft_tx_prepared(c) for s in self.stores.values() for c in (A, B))
        return applied and not prepared and not self.running

    def _pending(self) -> str:
        prepared = sum(len(s.raft_tx_prepared(c)) for s in self.stores.values() for c in (A, B))
        return f"{prepared} prepared, {self.running} running"

    # -- the logs and the replicas ---------------------------------------------------------
    def propose(
        self, n: int, chunk: ChunkId, entry: LogEntry, answer: Callable[[Any], None]
    ) -> None:
        """Node `n` proposes `entry` to `chunk`'s log; `answer` gets the `Outcome` when
        its replica applies it, or None after `TIMEOUT` if lost (unless `n` crashed)."""
        epoch = self.epoch[n]

        def reply(outcome: Outcome | None) -> None:
            if self.epoch[n] == epoch and self.alive[n]:
                answer(outcome)

        def arrive() -> None:
            if self.rng.random() < self.world.lost:
                self.at(TIMEOUT, lambda: reply(None))
                return
            self.logs[chunk].append(codec.encode_entry(entry))
            if self.rng.random() < self.world.answer_lost:
                self.at(TIMEOUT, lambda: reply(None))
            else:
                self.waiting[(n, chunk, len(self.logs[chunk]))] = (epoch, reply)

        self.at(1 + self.rng.randrange(self.world.max_delay), arrive)

    def _applied(self, n: int, chunk: ChunkId) -> int:
        kept = self.stores[n].raft_load(chunk)
        return 0 if kept is None else kept.applied

    def _apply_round(self) -> None:
        self.at(2, self._apply_round)
        for n, store in self.stores.items():
            for chunk in (A, B):
                index = self._applied(n, chunk) + 1
                if not self.alive[n] or index > len(self.logs[chunk]):
                    continue
                if self.rng.random() < self.world.lag:
                    continue
                entry = Entry(1, index, EntryKind.NORMAL, self.logs[chunk][index - 1])
                with store.exclusive():
                    applied = applier(store)(chunk, entry)
                    store.raft_applied(chunk, index, applied.time)
                waiter = self.waiting.pop((n, chunk, index), None)
                if waiter is not None:
                    waiter[1](applied.result)

    def _crash(self) -> None:
        if not self.world.crash_every:
            return
        self.at(1 + int(self.rng.expovariate(1 / self.world.crash_every)), self._crash)
        n = self.rng.choice(list(self.stores))
        if self.alive[n]:
            self.alive[n], self.epoch[n] = False, self.epoch[n] + 1
            self.at(self.rng.randrange(10, 120), lambda: self.alive.__setitem__(n, True))

    # -- writers ------------------------------------------------------------------------
    def propose_waiting(
        self, n: int, chunk: ChunkId, entry: LogEntry, answer: Callable[[Answer], None]
    ) -> None:
        """As `LogCommits.propose`: a busy chunk is asked again a few times; the answer
        as the coordinator sees it."""

        def heard(outcome: Outcome | None, tries: int = 1) -> None:
            if outcome is None:
                answer(Answer(unknown="no answer in time"))
            elif outcome.busy and tries < BUSY_TRIES:
                self.busy += 1

                def again() -> None:
                    self.propose(n, chunk, entry, lambda o: heard(o, tries + 1))

                self.at(5 + self.rng.randrange(10), again)
            elif outcome.busy:
                answer(Answer(busy="the chunk stayed busy"))
            else:
                answer(Answer(outcome.prepared, outcome.conflicts, outcome.decision))

        self.propose(n, chunk, entry, heard)

    def _client(self) -> None:
        living = [n for n in self.stores if self.alive[n]]
        if not living:
            return
        n = self.rng.choice(living)
        store = self.stores[n]
        begin = min(store.raft_time(A), store.raft_time(B))
        held = balances(store, begin)
        src, dst = self.rng.sample(list(ACCOUNTS), 2)
        if held[src] < AMOUNT:
            return
        changes = [
            Change(Op.UPDATE, TABLE, item, ACCOUNTS[item], str(held[item] + delta).encode())
            for item, delta in ((src, -AMOUNT), (dst, AMOUNT))
        ]
        self._ids += 1
        cid = CommitId(f"{self._ids:032x}")
        chunks = tuple(sorted({ACCOUNTS[src], ACCOUNTS[dst]}))
        txn = Txn(cid, chunks)
        self.txns.append(txn)
        proposals = {
            c: Proposal(
                cid,
                begin + 1,
                PeerId(f"{n:032x}"),
                f"node {n}",
                "",
                f"move {AMOUNT}",
                begin,
                "snapshot",
                tuple(ch for ch in changes if ch.chunk_id == c),
                participants=chunks if len(chunks) > 1 else (),
            )
            for c in chunks
        }
        self.running += 1
        self._watch(n, lambda: txn.status != "pending", lambda: self._lost(txn))
        if len(chunks) == 1:
            self.propose_waiting(n, chunks[0], proposals[chunks[0]], lambda a: self._single(txn, a))
        else:
            self._coordinate(txn, n, TwoPhase(proposals))

    def _watch(self, n: int, finished: Callable[[], bool], gone: Callable[[], None]) -> None:
        """Call `gone` if node `n` crashes before `finished()`: whatever it was doing
        never hears back."""
        epoch = self.epoch[n]

        def look() -> None:
            if finished():
                return
            if self.epoch[n] != epoch:
                gone()
            else:
                self.at(TIMEOUT, look)

        self.at(TIMEOUT, look)

    def _lost(self, txn: Txn) -> None:
        """The writer crashed: it never learns how its transaction ended."""
        txn.status = "unknown"
        self.running -= 1

    def _single(self, txn: Txn, answer: Answer) -> None:
        if txn.status != "pending":
            return
        self.running -= 1
        if answer.unknown:
            txn.status = "unknown"
        elif answer.decision is None and not (answer.conflicts or answer.busy):
            txn.status = "acked"
        else:
            txn.status = "aborted"

    def _coordinate(self, txn: Txn, n: int, machine: TwoPhase) -> None:
        """Drive `machine` from node `n` as `LogCommits._run` does (a crash of `n`
        abandons it: its answers no longer arrive)."""

        def send(chunk: ChunkId, entry: LogEntry) -> None:
            self.propose_waiting(n, chunk, entry, lambda a: fed(chunk, a))

        def fed(chunk: ChunkId, answer: Answer) -> None:
            for c, e in machine.answered(chunk, answer):
                send(c, e)
            if machine.done and txn.status == "pending":
                self.running -= 1
                if machine.committed:
                    txn.status = "acked"
                else:
                    txn.status = "unknown" if machine.decision is None else "aborted"

        for c, e in machine.start():
            send(c, e)

    # -- recovery -----------------------------------------------------------------------
    def _recover_round(self) -> None:
        """The leader of each chunk (its lowest living node) settles old prepares."""
        self.at(10, self._recover_round)
        for chunk in (A, B):
            living = [n for n in self.stores if self.alive[n]]
            if not living:
                return
            leader = min(living)
            for cid, row in self.stores[leader].raft_tx_prepared(chunk):
                key = (chunk, cid)
                first_seen = self.seen.setdefault(key, self.now)
                if self.now - first_seen >= RECOVER_AFTER and key not in self.settling:
                    self._settle(leader, chunk, cid, row.data)

    def _settle(self, n: int, chunk: ChunkId, cid: CommitId, data: bytes) -> None:
        """`TxRecovery.settle`: abort on the first chunk's log, then follow its answer."""
        prepare = codec.decode_entry(data)
        assert isinstance(prepare, Proposal)
        first = prepare.participants[0]
        key = (chunk, cid)
        self.settling.add(key)
        self.running += 1

        ended: list[bool] = []

        def done() -> None:
            if not ended:  # the answer, or the watch once `n` crashed: whichever is first
                ended.append(True)
                self.settling.discard(key)
                self.running -= 1

        self._watch(n, lambda: bool(ended), done)

        def decided(answer: Answer) -> None:
            if answer.decision is None:
                done()  # not reached: the next round tries again
            elif chunk == first:
                self.settled += 1
                done()
            else:
                self.propose_waiting(n, chunk, answer.decision, followed)

        def followed(answer: Answer) -> None:
            self.settled += answer.decision is not None
            done()

        self.propose_waiting(n, first, TxDecision(cid, False), decided)

    # -- the checker ----------------------------------------------------------------------
    def check(self) -> None:
        """The end-of-run rules (see the module docstring)."""
        self.reads = check_stores(self.stores, self.txns)

    def counts(self) -> dict[str, int]:
        """What happened in this run, as numbers."""
        by = [t.status for t in self.txns]
        return {
            "transactions": len(by),
            "two_chunk": sum(len(t.chunks) > 1 for t in self.txns),
            "acked": by.count("acked"),
            "aborted": by.count("aborted"),
            "unknown": by.count("unknown"),
            "settled_by_recovery": self.settled,
            "busy_retries": self.busy,
            "entries": sum(map(len, self.logs.values())),
            "reads_checked": self.reads,
        }

    def summary(self) -> str:
        """One line: what happened in this run."""
        return f"seed {self.seed}: " + ", ".join(f"{k} {v}" for k, v in self.counts().items())
