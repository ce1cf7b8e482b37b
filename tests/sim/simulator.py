"""A deterministic simulator for `mapapi.swarm.raft`: real `RaftNode`s, fake network, fake clock.

Everything comes from one seed (FoundationDB / TigerBeetle VOPR style): per-message delay, drop,
duplication (and so reordering), symmetric and one-way partitions that heal, paused nodes,
crashes that lose whatever was not persisted through a `Ready`, restarts at a new address, log
compaction with snapshot catch-up, and single-server membership changes. Clients propose
counter increments and bank transfers. `Checker` asserts the Raft safety properties after every
event; `Sim.run` ends by healing everything and checking liveness and the client-visible results.
"""

from __future__ import annotations

import heapq
import json
import random
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

from mapapi.swarm.raft import RaftNode, RaftOptions
from mapapi.swarm.raft_types import (
    ConfChange,
    ConfChangeKind,
    Config,
    Entry,
    EntryKind,
    HardState,
    Message,
    NotLeader,
    PersistentState,
    ProposalRefused,
    Ready,
    Role,
    Snapshot,
)

TICK = 10  # simulated time units per tick
ACCOUNTS = 4
BALANCE = 100
A0 = 1000  # the counter's initial value


class Violation(AssertionError):
    """A safety or liveness property failed."""


class Disk:
    """What a node persisted: exactly what its `Ready`s (and compactions) handed over."""

    def __init__(self, state: PersistentState | None = None) -> None:
        state = state or PersistentState()
        self.hard_state: HardState = state.hard_state
        self.snapshot: Snapshot = state.snapshot
        self.entries: list[Entry] = list(state.entries)

    def save(self, rd: Ready) -> None:
        """Persist a Ready in the contract's order: snapshot, entries, hard state."""
        if rd.snapshot:
            self.snapshot, self.entries = rd.snapshot, []
        if rd.entries:
            keep = rd.entries[0].index - self.snapshot.index - 1
            self.entries[keep:] = rd.entries
        if rd.hard_state:
            self.hard_state = rd.hard_state

    def save_snapshot(self, snap: Snapshot) -> None:
        """Persist a compaction: the snapshot, then drop the entries it covers."""
        self.entries = self.entries[snap.index - self.snapshot.index :]
        self.snapshot = snap

    def state(self) -> PersistentState:
        """What a restarted node reads back."""
        return PersistentState(self.hard_state, self.snapshot, tuple(self.entries))


@dataclass
class Machine:
    """A node's state machine: a counter and bank accounts, rebuilt from snapshots."""

    applied: int = 0
    counter: int = A0
    accounts: list[int] = field(default_factory=lambda: [BALANCE] * ACCOUNTS)
    ops: list[int] = field(default_factory=list)  # op ids applied, in order

    def apply(self, entry: Entry) -> None:
        """Apply one committed entry (NOOP and CONF_CHANGE entries only move `applied`)."""
        if entry.index != self.applied + 1:
            raise Violation(f"applied {entry.index} after {self.applied}: a gap")
        self.applied = entry.index
        if entry.kind is not EntryKind.NORMAL:
            return
        op = json.loads(entry.data)
        if op["id"] in self.ops:
            raise Violation(f"op {op['id']} applied twice (index {entry.index})")
        self.ops.append(op["id"])
        if op["op"] == "inc":
            self.counter += op["by"]
        elif self.accounts[op["src"]] >= op["amount"]:
            self.accounts[op["src"]] -= op["amount"]
            self.accounts[op["dst"]] += op["amount"]

    def encode(self) -> bytes:
        """The snapshot payload."""
        return json.dumps([self.applied, self.counter, self.accounts, self.ops]).encode()

    @classmethod
    def decode(cls, data: bytes) -> Machine:
        """A machine from a snapshot payload."""
        if not data:
            return cls()
        applied, counter, accounts, ops = json.loads(data)
        return cls(applied, counter, accounts, ops)

    def digest(self) -> tuple[int, int, tuple[int, ...], int]:
        """What two machines at the same index must agree on."""
        return self.counter, sum(self.accounts), tuple(self.accounts), len(self.ops)


@dataclass
class SimNode:
    """One simulated process: a RaftNode, its disk, its state machine and its address."""

    id: int
    raft: RaftNode
    disk: Disk
    machine: Machine
    alive: bool = True
    address: int = 0  # bumped at each restart: messages to an old address are lost
    paused_until: int = 0
    missed: int = 0  # ticks missed while paused
    ready_due: bool = False


@dataclass
class Faults:
    """How hostile this seed's world is."""

    drop: float
    duplicate: float
    max_delay: int
    defer_ready: float  # chance a node leaves its Ready unprocessed for a while
    fault_every: int  # mean time units between fault events


class Checker:
    """Safety invariants, checked incrementally after every event (paper Fig. 3)."""

    def __init__(self) -> None:
        self.leaders: dict[int, int] = {}  # term -> leader (Election Safety)
        self.entries: dict[tuple[int, int], tuple[Any, int | None]] = {}  # Log Matching
        self.history: list[Entry] = []  # State Machine Safety: the one applied history
        self.bounds: list[int] = []  # per history entry: the lowest term it was applied at
        self.digests: dict[int, tuple[int, int, tuple[int, ...], int]] = {}

    def leader(self, node: SimNode) -> None:
        """Election Safety: at most one leader per term; Leader Completeness on election."""
        raft = node.raft
        if raft.role is not Role.LEADER:
            return
        first = self.leaders.get(raft.term)
        if first is not None:
            if first != node.id:
                raise Violation(f"two leaders in term {raft.term}: {first} and {node.id}")
            return
        self.leaders[raft.term] = node.id
        # Leader Completeness (paper §5.4): an entry committed in term T is in the log of every
        # leader of a later term. A node applies an entry at a term >= T, so `bounds` (the
        # lowest such term) is a safe stand-in for T. (A leader of an older term can still win
        # late, through delayed votes, without the entry: seed 708.)
        for entry, bound in zip(self.history, self.bounds, strict=True):
            if entry.index < raft.log.first_index or bound >= raft.term:
                continue
            if raft.log.term(entry.index) != entry.term:
                raise Violation(f"leader {node.id} of term {raft.term} lacks applied {entry}")

    def persisted(self, node: SimNode, entries: tuple[Entry, ...]) -> None:
        """Log Matching: one entry per (index, term), always after the same previous term."""
        for entry in entries:
            prev = node.raft.log.term(entry.index - 1)
            key, payload = (entry.index, entry.term), (entry.kind, entry.data)
            seen_payload, seen_prev = self.entries.setdefault(key, (payload, prev))
            if seen_payload != payload:
                raise Violation(f"node {node.id}: two different entries at {key}")
            if None not in (prev, seen_prev) and prev != seen_prev:
                raise Violation(f"node {node.id}: entry {key} after term {prev}, not {seen_prev}")
            if seen_prev is None:
                self.entries[key] = (payload, prev)

    def applied(self, node: SimNode, entry: Entry) -> None:
        """State Machine Safety: every node applies a prefix of one history."""
        if entry.index <= len(self.history):
            if self.history[entry.index - 1] != entry:
                raise Violation(
                    f"node {node.id} applied {entry}, others {self.history[entry.index - 1]}"
                )
            self.bounds[entry.index - 1] = min(self.bounds[entry.index - 1], node.raft.term)
        elif entry.index == len(self.history) + 1:
            self.history.append(entry)
            self.bounds.append(node.raft.term)
        else:
            raise Violation(
                f"node {node.id} applied {entry.index} past history {len(self.history)}"
            )
        self.state(node)

    def state(self, node: SimNode) -> None:
        """Machines at the same index agree; the bank total never changes."""
        m = node.machine
        if sum(m.accounts) != ACCOUNTS * BALANCE:
            raise Violation(f"node {node.id}: bank total {sum(m.accounts)} at {m.applied}")
        known = self.digests.setdefault(m.applied, m.digest())
        if known != m.digest():
            raise Violation(f"node {node.id} at {m.applied}: state {m.digest()} != {known}")


def world(rng: random.Random) -> Faults:
    """Draw how hostile the network and the nodes are, per seed."""
    return Faults(
        drop=rng.choice([0.0, 0.01, 0.05, 0.15]),
        duplicate=rng.choice([0.0, 0.02, 0.1]),
        max_delay=rng.choice([2, 8, 20, 40]),
        defer_ready=rng.choice([0.0, 0.2, 0.5]),
        fault_every=rng.choice([100, 300, 1000]),
    )


SIM_OPTIONS = RaftOptions(election_tick=10, heartbeat_tick=2, max_inflight=4, max_entries_per_msg=8)


class Sim:
    """N nodes of one Raft group driven by one seed.

    Args:
        seed: everything random derives from it, so a run replays exactly.
        nodes: how many processes; the first `voters` found the group, the rest may join.
        fault_ticks: how long faults and client load last, in ticks of each node.
        compact_after: compact a node's log once it has applied this many entries past its
            snapshot (None: drawn from the seed).
    """

    def __init__(
        self,
        seed: int,
        nodes: int = 5,
        voters: int = 3,
        fault_ticks: int = 200,
        compact_after: int | None = None,
        faults: Faults | None = None,
        options: RaftOptions = SIM_OPTIONS,
    ) -> None:
        self.seed, self.options = seed, options
        self.rng = random.Random(seed)
        self.faults = replace(faults) if faults else world(self.rng)  # heal() mutates it
        self.compact_after = compact_after or self.rng.choice([4, 16, 10**9])
        self.fault_end = fault_ticks * TICK
        self.now = self._seq = 0
        self._events: list[tuple[int, int, Callable[[], None]]] = []
        self.blocked: dict[tuple[int, int], int] = {}
        self.checker = Checker()
        self.trace: list[str] = []
        config = Config(frozenset(range(1, voters + 1)))
        self.nodes: dict[int, SimNode] = {}
        for nid in range(1, nodes + 1):
            disk = Disk(PersistentState.bootstrap(config) if nid <= voters else None)
            self.nodes[nid] = self._boot(nid, disk, 0)
        self.proposed: dict[int, dict[str, Any]] = {}
        self.pending: dict[int, dict[int, tuple[int, int]]] = {n: {} for n in self.nodes}
        self.acked: set[int] = set()
        self.failed: set[int] = set()
        self.unknown: set[int] = set()
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
        """Faults and load, then heal; raises `Violation` on any broken property."""
        for node in self.nodes.values():
            self.at(self.rng.randrange(1, TICK + 1), self._ticker(node.id, node.address))
        self.at(1, self._client)
        self.at(self.rng.randrange(self.faults.fault_every), self._fault)
        self.run_until(self.fault_end)
        self.heal()
        self.check_liveness()
        self.check_results()

    # -- nodes ---------------------------------------------------------------------------

    def _boot(self, nid: int, disk: Disk, address: int) -> SimNode:
        machine = Machine.decode(disk.snapshot.data)
        rng = random.Random(self.seed * 7919 + nid * 31 + address)
        raft = RaftNode(nid, disk.state(), rng, self.options, applied=machine.applied)
        return SimNode(nid, raft, disk, machine, address=address)

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
                node.raft.tick()
                self.after(node)

        return tick

    def after(self, node: SimNode) -> None:
        """Check the node, then drive its Ready now or (sometimes) a little later."""
        self.checker.leader(node)
        if node.ready_due or not node.raft.has_ready():
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
        """The driver loop of the Ready contract: persist, send, apply, advance."""
        raft = node.raft
        rd = raft.ready()
        self.checker.persisted(node, rd.entries)
        node.disk.save(rd)
        for m in rd.messages:
            self.send(m)
        if rd.snapshot:
            node.machine = Machine.decode(rd.snapshot.data)
            if node.machine.applied > len(self.checker.history):
                raise Violation(f"node {node.id} got snapshot {rd.snapshot.index} past history")
            self.checker.state(node)
        for entry in rd.committed_entries:
            node.machine.apply(entry)
            self.checker.applied(node, entry)
            self._client_result(node, entry)
        raft.advance(rd)
        if node.machine.applied - raft.log.snapshot.index >= self.compact_after:
            node.disk.save_snapshot(raft.compact(node.machine.applied, node.machine.encode()))
        self.checker.leader(node)

    def crash(self, nid: int) -> None:
        """Kill a process: its memory and unpersisted Ready are lost, its disk stays."""
        node = self.nodes[nid]
        node.alive = False
        self.unknown |= {op for _, op in self.pending[nid].values()}
        self.pending[nid].clear()
        self.trace.append(f"{self.now}: crash {nid}")

    def restart(self, nid: int) -> None:
        """Start a crashed process again from its disk, at a new address."""
        old = self.nodes[nid]
        if old.alive:
            return
        node = self._boot(nid, old.disk, old.address + 1)
        self.nodes[nid] = node
        self.trace.append(f"{self.now}: restart {nid}")
        self.at(self.rng.randrange(1, TICK + 1), self._ticker(nid, node.address))
        self.checker.state(node)  # it re-applies from its snapshot on, through Readys

    # -- network -------------------------------------------------------------------------

    def send(self, m: Message) -> None:
        """Put a message on the wire: maybe dropped, maybe twice, after a random delay."""
        dest = self.nodes.get(m.to)
        if dest is None or self.rng.random() < self.faults.drop:
            return
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
        """Propose an increment or a transfer to the node believed to lead."""
        if self.now < self.fault_end:
            self.at(self.rng.randrange(2, 3 * TICK), self._client)
        node = self.nodes[self.leader_hint]
        if not node.alive or self.now < node.paused_until:
            self.leader_hint = self.rng.choice(list(self.nodes))
            return
        op_id = len(self.proposed) + 1
        if self.rng.random() < 0.5:
            op: dict[str, Any] = {"op": "inc", "id": op_id, "by": self.rng.randint(1, 5)}
        else:
            src, dst = self.rng.sample(range(ACCOUNTS), 2)
            op = {"op": "xfer", "id": op_id, "src": src, "dst": dst, "amount": 30}
        self.propose(node, op)

    def propose(self, node: SimNode, op: dict[str, Any]) -> int | None:
        """Propose `op` at `node`; its index, or None if refused (the hint is followed)."""
        try:
            index, term = node.raft.propose(json.dumps(op).encode())
        except NotLeader as err:
            self.leader_hint = err.leader or self.rng.choice(list(self.nodes))
            return None
        self.proposed[op["id"]] = op
        self.pending[node.id][index] = (term, op["id"])
        self.after(node)
        return index

    def _client_result(self, node: SimNode, entry: Entry) -> None:
        """A node applied `entry`: the client waiting on that index learns its fate."""
        waiting = self.pending[node.id].pop(entry.index, None)
        if waiting is None:
            return
        term, op_id = waiting
        (self.acked if entry.term == term else self.failed).add(op_id)

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
        return [
            n
            for n in self.nodes.values()
            if n.alive and n.raft.role is Role.LEADER and self.now >= n.paused_until
        ]

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
                op = {"op": "inc", "id": len(self.proposed) + 1, "by": 1}
                index = self.propose(leaders[0], op)
                target = (leaders[0], index) if index else None
            if target is None:
                continue
            leader, index = target
            if not (leader.raft.role is Role.LEADER and leader.alive):
                target = None  # it lost leadership before committing; ask the new one
                continue
            members = [self.nodes[n] for n in leader.raft.config.members]
            if all(m.machine.applied >= index for m in members):
                return (self.now - deadline) // TICK + ticks
        raise Violation(f"no leader committed within {ticks} ticks of healing")

    def check_results(self) -> None:
        """Acknowledged ops are in the history; the counter adds up; failed ops are absent."""
        applied = [json.loads(e.data) for e in self.checker.history if e.kind is EntryKind.NORMAL]
        ids = {op["id"] for op in applied}
        if lost := self.acked - ids:
            raise Violation(f"acknowledged ops lost: {sorted(lost)[:10]}")
        if ghosts := self.failed & ids:
            raise Violation(f"ops reported failed were applied: {sorted(ghosts)[:10]}")
        a0_plus_acked = A0 + sum(op["by"] for op in applied if op["op"] == "inc")
        for node in self.nodes.values():
            m = node.machine
            if m.applied == len(self.checker.history) and m.counter != a0_plus_acked:
                raise Violation(f"node {node.id}: counter {m.counter} != {a0_plus_acked}")

    def summary(self) -> str:
        """One line: what happened in this run."""
        terms = max(self.checker.leaders, default=0)
        return (
            f"seed {self.seed}: {len(self.checker.history)} entries, {len(self.acked)} acked, "
            f"{len(self.failed)} failed, {len(self.unknown)} unknown, {terms} terms, {self.faults}"
        )
