"""A deterministic simulator of a chunk's Raft group: real `RaftNode`s, fake network and clock.

Everything comes from one seed (FoundationDB / TigerBeetle VOPR style): per-message delay, drop,
duplication (and so reordering), symmetric and one-way partitions that heal, paused nodes,
crashes that lose whatever was not persisted through a `Ready`, restarts at a new address, log
compaction with snapshot catch-up, and single-server membership changes. `Checker`
(`mapbench.sim_world`) asserts the Raft safety properties after every event; `Sim.run` ends by
healing everything and checking liveness and the client-visible results.

Two workloads (`mapbench.sim_clients`): the pure core's (clients propose opaque increments and
transfers the simulator applies itself), and the commit path's (`commits=True`): each node holds
a real `MemoryStore` replica of the chunk, clients begin at a node's chunk clock, read, and
propose encoded `Proposal`s that every node decides with `apply_proposal`, as real writers and
holders do. Transactions over two chunks have their own simulation (`mapbench.sim_tx`).
`run_seeds` runs many seeds of each for `mapctl bench sim`; `tests/sim` runs them in CI.
"""

from __future__ import annotations

import heapq
import random
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

from mapapi.swarm.raft import RaftNode
from mapapi.swarm.raft_types import (
    ConfChange,
    ConfChangeKind,
    Config,
    Message,
    NotLeader,
    PersistentState,
    ProposalRefused,
    RaftOptions,
    Ready,
    Role,
)
from mapbench.sim_clients import CommitWorkload, CounterWorkload, Workload
from mapbench.sim_tx import TxSim
from mapbench.sim_world import (
    SIM_OPTIONS,
    TICK,
    Checker,
    Faults,
    NodeDisk,
    Replica,
    Violation,
    world,
)

SHAPES = ((5, 3), (5, 3), (3, 3), (7, 5), (4, 1), (2, 1))
"""(nodes, founding voters) a commit-path seed draws from: the default group of three
voters with two more holders, three alone, five, and a robot's own chunk (one voter, the
other holders learners)."""

__all__ = ["TICK", "Faults", "Sim", "SimNode", "Violation", "run_seeds"]


@dataclass
class SimNode:
    """One simulated process: a RaftNode, its disk, its state machine and its address."""

    id: int
    raft: RaftNode
    disk: NodeDisk
    replica: Replica
    alive: bool = True
    address: int = 0  # bumped at each restart: messages to an old address are lost
    paused_until: int = 0
    missed: int = 0  # ticks missed while paused
    ready_due: bool = False
    writing: bool = False  # a Ready taken, its write not yet done


class Sim:
    """N nodes of one Raft group driven by one seed.

    Args:
        seed: everything random derives from it, so a run replays exactly.
        nodes: how many processes; the first `voters` found the group, the rest may join
            (None: 5 and 3 for the pure core; for the commit path, drawn from `SHAPES`).
        fault_ticks: how long faults and client load last, in ticks of each node.
        compact_after: compact a node's log once it has applied this many entries past its
            snapshot (None: drawn from the seed).
        commits: run the commit path (stores, proposals, `apply_proposal`), not the pure
            core's counter.
    """

    def __init__(
        self,
        seed: int,
        nodes: int | None = None,
        voters: int | None = None,
        fault_ticks: int = 200,
        compact_after: int | None = None,
        faults: Faults | None = None,
        options: RaftOptions = SIM_OPTIONS,
        commits: bool = False,
    ) -> None:
        self.seed = seed
        # Half the seeds let idle groups go quiet (drawn apart, so the rest of a seed's
        # run does not change with it).
        quiet = random.Random(seed * 7907 + 3).random() < 0.5
        self.options = replace(options, quiesce=options.quiesce or quiet)
        self.rng = random.Random(seed)
        self.faults = replace(faults) if faults else world(self.rng)  # heal() mutates it
        # Writes that end later, as a peer's Ready persisted in a worker thread while its
        # loop steps on (`swarm/ready_disk.py`): drawn apart, as the quiet groups are.
        self._disk_rng = random.Random(seed * 7907 + 5)
        self.slow_writes = 0
        if faults is None:
            self.faults.slow_disk = self._disk_rng.choice([0.0, 0.0, 0.3, 0.7])
        self.compact_after = compact_after or self.rng.choice([4, 16, 10**9])
        if nodes is None or voters is None:
            drawn = self.rng.choice(SHAPES) if commits else (5, 3)
            nodes, voters = nodes or drawn[0], voters or drawn[1]
        self.shape = (nodes, voters)
        self.fault_end = fault_ticks * TICK
        self.now = self._seq = 0
        self._events: list[tuple[int, int, Callable[[], None]]] = []
        self.blocked: dict[tuple[int, int], int] = {}
        self.checker = Checker()
        self.trace: list[str] = []
        self.workload: Workload = CommitWorkload(self) if commits else CounterWorkload(self)
        config = Config(frozenset(range(1, voters + 1)))
        # the founders' identical first entry: applied at founding in a store (as
        # `RaftGroups.found` does), through a Ready by the pure core's machines
        self.checker.history = list(PersistentState.bootstrap(config).entries)
        self.checker.bounds = [1]
        for entry in self.checker.history:
            self.checker.entries[(entry.index, entry.term)] = ((entry.kind, entry.data), 0)
        self.nodes: dict[int, SimNode] = {}
        for nid in range(1, nodes + 1):
            disk = self.workload.new_disk(nid, config if nid <= voters else None)
            self.nodes[nid] = self._boot(nid, disk, 0)
        self.pending: dict[int, dict[int, tuple[int, Any]]] = {n: {} for n in self.nodes}
        self.proposed: set[Any] = set()
        self.acked: set[Any] = set()
        self.failed: set[Any] = set()
        self.unknown: set[Any] = set()
        self.leader_hint = 1

    # -- the event loop ------------------------------------------------------------------

    def at(self, delay: int, action: Callable[[], None]) -> None:
        """Run `action` `delay` time units from now."""
        self._seq += 1
        heapq.heappush(self._events, (self.now + delay, self._seq, action))

    def run_until(self, until: int) -> None:
        """Process every event due up to time `until`."""
        while self._events and self._events[0][0] <= until:
            self.now, _, action = heapq.heappop(self._events)
            action()
        self.now = max(self.now, until)

    def run(self) -> None:
        """Faults and load, then heal; raises `Violation` on any broken property (an
        exception from the code under test is reported as one too)."""
        try:
            for node in self.nodes.values():
                self.at(self.rng.randrange(1, TICK + 1), self._ticker(node.id, node.address))
            self.at(1, self._client)
            self.at(self.rng.randrange(self.faults.fault_every), self._fault)
            self.run_until(self.fault_end)
            self.heal()
            self.check_liveness()
            self.unknown |= {
                key for waiting in self.pending.values() for _, key in waiting.values()
            }
            self.workload.check_results()
        except Violation:
            raise
        except Exception as exc:
            raise Violation(f"{type(exc).__name__}: {exc}") from exc

    # -- nodes ---------------------------------------------------------------------------

    def _boot(self, nid: int, disk: NodeDisk, address: int) -> SimNode:
        replica = self.workload.replica(nid, disk)
        rng = random.Random(self.seed * 7919 + nid * 31 + address)
        raft = RaftNode(nid, disk.state(), rng, self.options, applied=replica.applied)
        return SimNode(nid, raft, disk, replica, address=address)

    def usable(self, node: SimNode) -> bool:
        """Whether the node runs now (alive and not paused)."""
        return node.alive and self.now >= node.paused_until

    def _ticker(self, nid: int, address: int) -> Callable[[], None]:
        def tick() -> None:
            node = self.nodes[nid]
            if not node.alive or node.address != address:
                return  # this process is gone; its restart runs its own ticker
            self.at(TICK, tick)
            if self.now < node.paused_until:
                node.missed += 1
                return
            # A loop blocked for a while may fire its timer late, all at once.
            burst = 1 + self.rng.randrange(node.missed + 1)
            node.missed = 0
            for _ in range(min(burst, 3 * self.options.election_tick)):
                node.raft.tick(leader_alive=self._hears_leader(node))
                self.after(node)

        return tick

    def _hears_leader(self, node: SimNode) -> bool:
        """The peer-level failure detector of a quiet follower: its leader's process
        runs and reaches it (a perfect detector; a real one lags, which costs time,
        never safety)."""
        leader = self.nodes.get(node.raft.leader)
        return (
            leader is not None and self.usable(leader) and (leader.id, node.id) not in self.blocked
        )

    def after(self, node: SimNode) -> None:
        """Check the node, then drive its Ready now or (sometimes) a little later."""
        self.checker.leader(node)
        if node.ready_due or node.writing or not node.raft.has_ready():
            return
        if self.rng.random() < self.faults.defer_ready:
            node.ready_due = True
            address = node.address

            def flush() -> None:
                if node.alive and node.address == address:
                    node.ready_due = False
                    self.after(node)

            self.at(self.rng.randrange(1, 3 * TICK), flush)
            return
        self.process_ready(node)

    def process_ready(self, node: SimNode) -> None:
        """Take the node's Ready and handle it, now or once its write ends later
        (messages and ticks step the node meanwhile; a crash loses the write)."""
        rd = node.raft.ready()
        if self._disk_rng.random() >= self.faults.slow_disk:
            self._handle_ready(node, rd)
            return
        node.writing = True
        self.slow_writes += 1
        address = node.address

        def written() -> None:
            if node.alive and node.address == address:
                node.writing = False
                self._handle_ready(node, rd)
                self.after(node)

        self.at(self._disk_rng.randrange(1, 2 * TICK), written)

    def _handle_ready(self, node: SimNode, rd: Ready) -> None:
        """The driver loop of the Ready contract: persist, send, apply, advance."""
        raft, replica = node.raft, node.replica
        self.checker.persisted(node, rd.entries)
        node.disk.save(rd)
        for m in rd.messages:
            self.send(m)
        if rd.snapshot:
            replica.install(rd.snapshot)
            if replica.applied > len(self.checker.history):
                raise Violation(f"node {node.id} got snapshot {rd.snapshot.index} past history")
            self.checker.state(node)
            self._forget_waiting(node, rd.snapshot.index)
        results = []
        with replica.batch():  # the effects and the applied index, together
            for entry in rd.committed_entries:
                results.append((entry, replica.apply(entry)))
                self.checker.applied(node, entry)
        for entry, result in results:  # proposers learn after the transaction
            self._client_result(node, entry, result)
        raft.advance(rd)
        if replica.applied - raft.log.snapshot.index >= self.compact_after:
            node.disk.save_snapshot(raft.compact(replica.applied, replica.snapshot_data()))
        self.checker.leader(node)

    def _forget_waiting(self, node: SimNode, index: int) -> None:
        """Proposals a snapshot jumped over never learn their outcome here: unknown."""
        waiting = self.pending[node.id]
        for i in [i for i in waiting if i <= index]:
            self.unknown.add(waiting.pop(i)[1])

    def crash(self, nid: int) -> None:
        """Kill a process: its memory and unpersisted Ready are lost, its disk stays."""
        node = self.nodes[nid]
        node.alive = False
        self.unknown |= {key for _, key in self.pending[nid].values()}
        self.pending[nid].clear()
        self.trace.append(f"{self.now}: crash {nid}")

    def restart(self, nid: int) -> None:
        """Start a crashed process again from its disk, at a new address."""
        old = self.nodes[nid]
        if old.alive:
            return
        node = self._boot(nid, old.disk, old.address + 1)
        self.checker.reloaded(node, old.disk.state())
        self.nodes[nid] = node
        self.trace.append(f"{self.now}: restart {nid}")
        self.at(self.rng.randrange(1, TICK + 1), self._ticker(nid, node.address))
        self.checker.state(node)  # it re-applies from its applied index on, through Readys

    # -- network -------------------------------------------------------------------------

    def send(self, m: Message) -> None:
        """Put a message on the wire: maybe dropped, maybe twice, after a random delay."""
        dest = self.nodes.get(m.to)
        if dest is None or self.rng.random() < self.faults.drop:
            return
        m = self.workload.wire(m)
        copies = 2 if self.rng.random() < self.faults.duplicate else 1
        for _ in range(copies):
            self.at(self.rng.randint(1, self.faults.max_delay), self._delivery(m, dest.address))

    def _delivery(self, m: Message, address: int) -> Callable[[], None]:
        def deliver() -> None:
            node = self.nodes[m.to]
            if not node.alive or node.address != address or (m.sender, m.to) in self.blocked:
                return
            if self.now < node.paused_until:
                self.at(node.paused_until - self.now + self.rng.randrange(1, 5), deliver)
                return
            node.raft.step(m)
            self.after(node)

        return deliver

    # -- clients -------------------------------------------------------------------------

    def _client(self) -> None:
        """One client action at the node believed to lead (a new hint if it is down)."""
        if self.now < self.fault_end:
            self.at(self.rng.randrange(2, 3 * TICK), self._client)
        node = self.nodes[self.leader_hint]
        if not self.usable(node):
            self.leader_hint = self.rng.choice(list(self.nodes))
            return
        self.workload.client(node)

    def propose(self, node: SimNode, key: Any, data: bytes) -> int | None:
        """Propose `data` at `node` for the client op `key`; its index, or None if refused
        (the client follows the hint)."""
        try:
            index, term = node.raft.propose(data)
        except NotLeader as err:
            self.leader_hint = err.leader or self.rng.choice(list(self.nodes))
            return None
        self.proposed.add(key)
        self.pending[node.id][index] = (term, key)
        self.after(node)
        return index

    def _client_result(self, node: SimNode, entry: Any, result: object) -> None:
        """A node applied `entry`: the client waiting on that index learns its fate."""
        waiting = self.pending[node.id].pop(entry.index, None)
        if waiting is None:
            return
        term, key = waiting
        if entry.term != term:
            self.failed.add(key)
        else:
            self.workload.outcome(key, entry, result)

    # -- faults --------------------------------------------------------------------------

    def _fault(self) -> None:
        if self.now >= self.fault_end:
            return
        self.at(1 + int(self.rng.expovariate(1 / self.faults.fault_every)), self._fault)
        kind = self.rng.choice(["partition", "one-way", "pause", "crash", "member", "member"])
        nid = self.rng.choice(list(self.nodes))
        duration = self.rng.randrange(TICK, 50 * TICK)
        self.trace.append(f"{self.now}: {kind} {nid} for {duration}")
        if kind in ("partition", "one-way"):
            side = set(self.rng.sample(list(self.nodes), self.rng.randint(1, 2)))
            pairs = [(a, b) for a in side for b in self.nodes if b not in side]
            if kind == "partition":
                pairs += [(b, a) for a, b in pairs]
            elif self.rng.random() < 0.5:
                pairs = [(b, a) for a, b in pairs]
            for pair in pairs:
                self.blocked[pair] = self.blocked.get(pair, 0) + 1
            self.at(duration, lambda: self._unblock(pairs))
        elif kind == "pause":
            node = self.nodes[nid]
            node.paused_until = max(node.paused_until, self.now + duration)
        elif kind == "crash" and self.nodes[nid].alive:
            self.crash(nid)
            self.at(duration, lambda: self.restart(nid))
        elif kind == "member":
            self.change_membership()

    def _unblock(self, pairs: list[tuple[int, int]]) -> None:
        for pair in pairs:
            if pair in self.blocked:  # heal() may have cleared it already
                self.blocked[pair] -= 1
                if not self.blocked[pair]:
                    del self.blocked[pair]

    def leaders(self) -> list[SimNode]:
        """Live, running nodes that believe they lead."""
        return [n for n in self.nodes.values() if self.usable(n) and n.raft.role is Role.LEADER]

    def change_membership(self) -> None:
        """At a leader: add a learner, promote one, or remove a member (maybe the leader)."""
        for node in self.leaders():
            config = node.raft.config
            outside = [n for n in self.nodes if n not in config.members]
            choices = [ConfChange(ConfChangeKind.ADD_LEARNER, n) for n in outside]
            choices += [ConfChange(ConfChangeKind.ADD_VOTER, n) for n in sorted(config.learners)]
            choices += [ConfChange(ConfChangeKind.REMOVE_NODE, n) for n in sorted(config.members)]
            change = self.rng.choice(choices)
            try:
                node.raft.propose_conf_change(change)
            except (ProposalRefused, ValueError):
                return
            self.trace.append(f"{self.now}: node {node.id} proposes {change}")
            self.after(node)
            return

    def heal(self) -> None:
        """Faults stop: partitions heal, paused nodes resume, crashed ones restart."""
        self.blocked.clear()
        self.faults.drop = self.faults.duplicate = self.faults.defer_ready = 0.0
        for nid, node in self.nodes.items():
            node.paused_until = min(node.paused_until, self.now)
            if not node.alive:
                self.restart(nid)

    # -- end-of-run checks ---------------------------------------------------------------

    def check_liveness(self, ticks: int = 100) -> int:
        """After healing, a leader commits a fresh entry that every member applies.

        Returns:
            the ticks it took.
        """
        deadline = self.now + ticks * TICK
        target: tuple[SimNode, int] | None = None
        while self.now < deadline:
            self.run_until(self.now + TICK)
            leaders = self.leaders()
            if target is None and leaders:
                index = self.workload.probe(leaders[0])
                target = (leaders[0], index) if index else None
            if target is None:
                continue
            leader, index = target
            if not (leader.raft.role is Role.LEADER and leader.alive):
                target = None  # it lost leadership before committing; ask the new one
                continue
            members = [self.nodes[n] for n in leader.raft.config.members]
            if all(m.replica.applied >= index for m in members):
                return (self.now - deadline) // TICK + ticks
        raise Violation(f"no leader committed within {ticks} ticks of healing")

    def summary(self) -> str:
        """One line: what happened in this run."""
        terms = max(self.checker.leaders, default=0)
        return (
            f"seed {self.seed}: {self.shape[0]} nodes, {self.shape[1]} voters, "
            f"{len(self.checker.history)} entries, {len(self.acked)} acked, "
            f"{len(self.failed)} failed, {len(self.unknown)} unknown, {terms} terms, "
            f"{self.workload.summary()}{self.faults}"
        )

    def counts(self) -> dict[str, int]:
        """What happened in this run, as numbers."""
        return {
            "entries": len(self.checker.history),
            "proposed": len(self.proposed),
            "acked": len(self.acked),
            "failed": len(self.failed),
            "unknown": len(self.unknown),
            "terms": max(self.checker.leaders, default=0),
            "slow_writes": self.slow_writes,
            **self.workload.counts(),
        }


def replay_command(seed: int, tests: str = "seed") -> str:
    """The one command that replays a seed in the test suite (`tests`: pytest's `-k`,
    "seed" for the core and the commit path, "tx_seed" for transactions), with the
    Python `make test` installs."""
    return f"SIM_SEED={seed} .venv/bin/python -m pytest tests/sim -k {tests} -s"


def run_seeds(
    first: int, count: int, modes: tuple[str, ...] = ("core", "commits", "tx")
) -> dict[str, Any]:
    """Run seeds `first` .. `first + count - 1` in each mode ("core": the pure Raft core's
    counter; "commits": the commit path on stores; "tx": transactions over two chunks,
    `mapbench.sim_tx`); violations and summed counts.

    Nothing here asserts: a violation is reported with its replay command.
    """
    started = time.perf_counter()
    totals: dict[str, dict[str, int]] = {mode: {} for mode in modes}
    violations: list[dict[str, Any]] = []
    for mode in modes:
        for seed in range(first, first + count):
            sim: Sim | TxSim = TxSim(seed) if mode == "tx" else Sim(seed, commits=mode == "commits")
            try:
                sim.run()
            except Violation as err:
                violations.append(
                    {"mode": mode, "seed": seed, "error": str(err), "replay": replay_command(seed)}
                )
            for name, n in sim.counts().items():
                totals[mode][name] = totals[mode].get(name, 0) + n
    return {
        "first": first,
        "seeds": count,
        "runs": count * len(modes),
        "violations": violations,
        "seconds": round(time.perf_counter() - started, 2),
        **{mode: totals[mode] for mode in modes},
    }
