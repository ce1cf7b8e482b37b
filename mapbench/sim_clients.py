"""The simulator's workloads (`mapbench.sim`): what nodes hold and what clients do.

`CounterWorkload` drives the pure Raft core: clients propose opaque JSON increments and
transfers that the simulator's `Machine` applies itself. `CommitWorkload` drives the commit
path: each node holds a `MemoryStore` replica (`mapbench.sim_store`), and clients behave like
real writers: they begin at a node's chunk clock (the leader's, or a stale follower's), read the
counter or two accounts there, propose a `Proposal` (snapshot isolation for increments,
serializable with the read set for transfers), and learn the outcome when the entry applies at
the node they proposed to: committed (acknowledged), conflicting (retried from a new begin),
lost to a new leader (failed) or never learnt (unknown).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

from mapapi.core import codec
from mapapi.core.change import Change, Op
from mapapi.core.ids import CommitId, ItemId, PeerId
from mapapi.core.proposal import Proposal
from mapapi.core.view import Scope
from mapapi.store.base import ReplicaStore
from mapapi.swarm.apply import Outcome
from mapapi.swarm.chain_check import check_chain
from mapapi.swarm.raft_types import Config, Entry, EntryKind, Message, PersistentState
from mapbench.sim_store import (
    ACCOUNT_IDS,
    AUDIT,
    CHUNK,
    COUNTER,
    TABLE,
    TOTAL,
    ChunkReplica,
    CommitHistory,
    StoreDisk,
    commit_id,
    new_store,
    peer,
    value,
    wire,
)
from mapbench.sim_world import A0, ACCOUNTS, TICK, Disk, Machine, NodeDisk, Replica, Violation

if TYPE_CHECKING:
    from mapbench.sim import Sim, SimNode

STALE_READS = 0.25
"""Share of client transactions that begin at a (maybe stale) follower's clock."""
MAX_ATTEMPTS = 5
"""Tries of one client operation that keeps conflicting."""
AMOUNT = 30
"""What one transfer moves."""
IN_FLIGHT = 4
"""New client operations wait while this many proposals wait for their outcome (retries
do not): writers are a few robots, each waiting for its commit, not an open stream."""
ENVELOPE_EVERY = 8
"""One message in this many (and every snapshot) goes through the envelope codec."""


class Workload(Protocol):
    """What the nodes hold and what the clients do, for one run."""

    def new_disk(self, nid: int, config: Config | None) -> NodeDisk:
        """A node's disk at the start: a founding voter's (`config`) or a joiner's (None)."""

    def replica(self, nid: int, disk: NodeDisk) -> Replica:
        """The node's state machine as it (re)starts from `disk`."""

    def wire(self, m: Message) -> Message:
        """A message as it arrives (the same, or through the real wire codec)."""

    def client(self, node: SimNode) -> None:
        """One client operation at `node` (the node believed to lead)."""

    def probe(self, node: SimNode) -> int | None:
        """Propose one increment at `node` (the liveness check); its index or None."""

    def outcome(self, key: Any, entry: Entry, result: object) -> None:
        """The proposal `key` was applied, as `entry`, at the node it was proposed to."""

    def check_results(self) -> None:
        """End of run: what clients were told agrees with what the replicas hold."""

    def summary(self) -> str:
        """Workload figures for `Sim.summary` ("" or ending with ", ")."""

    def counts(self) -> dict[str, int]:
        """Workload figures for `Sim.counts`."""


class CounterWorkload:
    """The pure core's workload: JSON ops applied by the simulator's `Machine`."""

    def __init__(self, sim: Sim) -> None:
        self.sim = sim
        self.ops: dict[int, dict[str, Any]] = {}

    def new_disk(self, nid: int, config: Config | None) -> NodeDisk:
        """An in-memory disk, with the bootstrap entry for a founding voter."""
        return Disk(PersistentState.bootstrap(config) if config else None)

    def replica(self, nid: int, disk: NodeDisk) -> Replica:
        """The machine of the disk's snapshot (the node re-applies entries after it)."""
        return Machine.decode(disk.state().snapshot.data)

    def wire(self, m: Message) -> Message:
        """Messages travel as they are."""
        return m

    def client(self, node: SimNode) -> None:
        """Propose an increment or a transfer."""
        rng = self.sim.rng
        op_id = len(self.ops) + 1
        if rng.random() < 0.5:
            op: dict[str, Any] = {"op": "inc", "id": op_id, "by": rng.randint(1, 5)}
        else:
            src, dst = rng.sample(range(ACCOUNTS), 2)
            op = {"op": "xfer", "id": op_id, "src": src, "dst": dst, "amount": AMOUNT}
        self._propose(node, op)

    def probe(self, node: SimNode) -> int | None:
        """Propose an increment by 1."""
        return self._propose(node, {"op": "inc", "id": len(self.ops) + 1, "by": 1})

    def _propose(self, node: SimNode, op: dict[str, Any]) -> int | None:
        index = self.sim.propose(node, op["id"], json.dumps(op).encode())
        if index is not None:
            self.ops[op["id"]] = op
        return index

    def outcome(self, key: Any, entry: Entry, result: object) -> None:
        """Applied in the client's term: acknowledged."""
        self.sim.acked.add(key)

    def check_results(self) -> None:
        """Acknowledged ops are in the history; the counter adds up; failed ops are absent."""
        sim = self.sim
        history = sim.checker.history
        applied = [json.loads(e.data) for e in history if e.kind is EntryKind.NORMAL]
        ids = {op["id"] for op in applied}
        if lost := sim.acked - ids:
            raise Violation(f"acknowledged ops lost: {sorted(lost)[:10]}")
        if ghosts := sim.failed & ids:
            raise Violation(f"ops reported failed were applied: {sorted(ghosts)[:10]}")
        a0_plus_applied = A0 + sum(op["by"] for op in applied if op["op"] == "inc")
        for node in sim.nodes.values():
            m = node.replica
            if not isinstance(m, Machine):
                raise TypeError(f"node {node.id} holds a {type(m).__name__}")
            if m.applied == len(history) and m.counter != a0_plus_applied:
                raise Violation(f"node {node.id}: counter {m.counter} != {a0_plus_applied}")

    def summary(self) -> str:
        """Nothing beyond the Sim's figures."""
        return ""

    def counts(self) -> dict[str, int]:
        """Nothing beyond the Sim's figures."""
        return {}


Plan = tuple[tuple[Change, ...], frozenset[ItemId], frozenset[Scope]]
"""A client transaction's writes, read set and scanned scopes."""


@dataclass(frozen=True)
class ClientOp:
    """One client operation: an increment by `by`, a transfer `src` -> `dst`, or an audit
    (a serializable scan of the chunk that writes the bank total it read)."""

    id: int
    kind: str
    by: int = 0
    src: int = 0
    dst: int = 0


class CommitWorkload:
    """The commit path's workload (see the module docstring)."""

    def __init__(self, sim: Sim) -> None:
        self.sim = sim
        self.history = CommitHistory()
        self.ops: dict[int, ClientOp] = {}
        self.attempts: dict[CommitId, tuple[ClientOp, int]] = {}  # commit -> (op, try)
        self.conflicted: set[CommitId] = set()
        self.declined = self.gave_up = self.stale = self.sent = self.busy = 0

    def new_disk(self, nid: int, config: Config | None) -> NodeDisk:
        """The node's store, with the chunk's genesis and the group's state."""
        return StoreDisk(new_store(config))

    def replica(self, nid: int, disk: NodeDisk) -> Replica:
        """The store as the node (re)starts: applied as far as the store says."""
        if not isinstance(disk, StoreDisk):
            raise TypeError(f"node {nid} has a {type(disk).__name__}, not a store")
        return ChunkReplica(nid, disk.store, self.history)

    def wire(self, m: Message) -> Message:
        """Through `raft_wire`, and the envelope codec for every message with a snapshot
        and one in `ENVELOPE_EVERY` of the rest (the codec costs about 0.4 ms a message)."""
        self.sent += 1
        return wire(m, envelope=m.snapshot is not None or self.sent % ENVELOPE_EVERY == 0)

    def client(self, node: SimNode) -> None:
        """Begin a new increment, transfer or audit at `node`, unless `IN_FLIGHT` wait."""
        if sum(map(len, self.sim.pending.values())) >= IN_FLIGHT:
            self.busy += 1
            return
        rng = self.sim.rng
        n = len(self.ops) + 1
        draw = rng.random()
        if draw < 0.45:
            op = ClientOp(n, "inc", by=rng.randint(1, 5))
        elif draw < 0.85:
            src, dst = rng.sample(range(ACCOUNTS), 2)
            op = ClientOp(n, "xfer", src=src, dst=dst)
        else:
            op = ClientOp(n, "audit")
        self.ops[n] = op
        self.attempt(node, op, 1)

    def probe(self, node: SimNode) -> int | None:
        """An increment by 1, read at `node` itself."""
        op = ClientOp(len(self.ops) + 1, "inc", by=1)
        self.ops[op.id] = op
        return self.attempt(node, op, 1, stale=False)

    def attempt(self, node: SimNode, op: ClientOp, attempt: int, stale: bool = True) -> int | None:
        """Begin, read, and propose `op` at `node`; the entry's index, or None."""
        sim = self.sim
        reader = node
        if stale and sim.rng.random() < STALE_READS:
            reader = sim.rng.choice([n for n in sim.nodes.values() if sim.usable(n)])
            self.stale += reader is not node
        if not isinstance(replica := reader.replica, ChunkReplica):
            raise TypeError(f"node {reader.id} holds a {type(replica).__name__}")
        begin = replica.store.raft_time(CHUNK)
        planned = self._plan(op, replica.store, begin)
        if planned is None:
            self.declined += 1
            return None
        changes, reads, scopes = planned
        cid = commit_id(len(self.attempts) + 1)
        proposal = Proposal(
            cid,
            begin + sim.rng.randint(1, 3),  # the writer's Lamport clock
            _author(node),
            f"client {op.id}",
            "",
            f"{op.kind} {op.id} try {attempt}",
            begin,
            "snapshot" if op.kind == "inc" else "serializable",
            changes,
            read_set=reads,
            scopes=scopes,
        )
        self.attempts[cid] = (op, attempt)
        if op.kind == "inc":
            self.history.increments[cid] = op.by
        return sim.propose(node, cid, codec.encode_entry(proposal))

    @staticmethod
    def _plan(op: ClientOp, store: ReplicaStore, begin: int) -> Plan | None:
        """What `op` writes, reads and scans, read at `begin` (None: a transfer the source
        cannot pay). Every read at a begin time sees a whole prefix of the log: the bank
        total holds there."""
        if op.kind == "inc":
            now = value(store.read(COUNTER, begin))
            return (_update(COUNTER, now + op.by),), frozenset(), frozenset()
        if op.kind == "audit":
            total = sum(value(store.read(i, begin)) for i in ACCOUNT_IDS)
            if total != TOTAL:
                raise Violation(f"a read at time {begin} saw a bank total of {total}")
            return (_update(AUDIT, total),), frozenset(), frozenset({(TABLE, CHUNK)})
        src, dst = ACCOUNT_IDS[op.src], ACCOUNT_IDS[op.dst]
        have, got = value(store.read(src, begin)), value(store.read(dst, begin))
        if have < AMOUNT:
            return None
        changes = (_update(src, have - AMOUNT), _update(dst, got + AMOUNT))
        return changes, frozenset({src, dst}), frozenset()

    def outcome(self, key: Any, entry: Entry, result: object) -> None:
        """Committed: acknowledged. Conflicting: begin again (up to `MAX_ATTEMPTS`)."""
        if not isinstance(result, Outcome):
            raise Violation(f"entry {entry.index} of {key} applied as {result!r}")
        if result.committed:
            self.sim.acked.add(key)
            return
        if not result.conflicts:
            raise Violation(f"{key} neither committed nor conflicted: {result}")
        self.conflicted.add(key)
        op, attempt = self.attempts[key]
        if attempt < MAX_ATTEMPTS:
            self.sim.at(self.sim.rng.randrange(1, TICK), lambda: self._retry(op, attempt + 1))
        else:
            self.gave_up += 1

    def _retry(self, op: ClientOp, attempt: int) -> None:
        node = self.sim.nodes[self.sim.leader_hint]
        if not self.sim.usable(node) or self.attempt(node, op, attempt) is None:
            self.gave_up += 1

    def check_results(self) -> None:
        """One history on every store; acknowledged commits present; the counter adds up."""
        sim = self.sim
        committed = set(self.history.ids)
        if lost := sim.acked - committed:
            raise Violation(f"acknowledged commits lost: {sorted(lost)[:5]}")
        if ghosts := (sim.failed | self.conflicted) & committed:
            raise Violation(f"commits reported failed or conflicting were applied: {ghosts}")
        incs = {c: self.attempts[c][0].by for c in self.history.ids if c in self.attempts}
        expected = A0 + sum(incs.values())
        acked = sum(by for c, by in incs.items() if c in sim.acked)
        unknown = sum(self.attempts[c][0].by for c in sim.unknown if c in self.attempts)
        last = len(sim.checker.history)
        for node in sim.nodes.values():
            replica = node.replica
            if not isinstance(replica, ChunkReplica):
                raise TypeError(f"node {node.id} holds a {type(replica).__name__}")
            self._check_replica(node.id, replica)
            counter, _ = replica.values()
            if replica.applied != last:
                continue
            if counter != expected:
                raise Violation(f"node {node.id}: counter {counter} != a0 + committed {expected}")
            if not 0 <= counter - A0 - acked <= unknown:
                raise Violation(
                    f"node {node.id}: counter {counter} - a0 - acked {acked} "
                    f"is not within the unknown outcomes' {unknown}"
                )

    def _check_replica(self, nid: int, replica: ChunkReplica) -> None:
        """The store holds what the replica applied, in log order, with a sound hash chain,
        and every acknowledged commit up to its applied index."""
        stored = replica._stored_commits()
        if stored != replica.commits:
            raise Violation(f"node {nid}: the store's commits differ from those it applied")
        self.history.check(nid, stored)
        for record in replica.store.chunk_commits(CHUNK):  # every past time reads a prefix
            total = sum(value(replica.store.read(i, record.time)) for i in ACCOUNT_IDS)
            if total != TOTAL:
                raise Violation(f"node {nid}: a read at {record.time} sees a total of {total}")
        if replica.store.chain_length(CHUNK) != len(stored) + 1:  # the genesis commit too
            raise Violation(f"node {nid}: its hash chain does not link every commit")
        if problems := check_chain(replica.store, CHUNK):
            raise Violation(f"node {nid}: {problems[0]}")
        kept = replica.store.raft_load(CHUNK)
        if kept is None or (kept.applied, kept.time) != (replica.applied, replica.time):
            raise Violation(f"node {nid}: the store's applied index or clock is not the replica's")
        for cid in self.sim.acked:
            if self.history.index[cid] <= replica.applied and cid not in stored:
                raise Violation(f"node {nid} applied past acknowledged {cid.short} without it")
            if cid in stored and not replica.store.commit_revisions(cid):
                raise Violation(f"node {nid}: acknowledged {cid.short} wrote nothing here")

    def summary(self) -> str:
        """Conflicts, give-ups, stale reads, declined transfers."""
        return ", ".join(f"{k} {v}" for k, v in self.counts().items()) + ", "

    def counts(self) -> dict[str, int]:
        """Commit-path figures."""
        return {
            "commits": len(self.history.ids),
            "conflicts": len(self.conflicted),
            "gave_up": self.gave_up,
            "stale_reads": self.stale,
            "declined": self.declined,
            "busy": self.busy,
        }


def _update(item: ItemId, amount: int) -> Change:
    return Change(Op.UPDATE, TABLE, item, CHUNK, str(amount).encode())


def _author(node: SimNode) -> PeerId:
    return peer(node.id)
