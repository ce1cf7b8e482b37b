"""The simulator's world (`mapbench.sim`): faults, disks, the pure state machine, the checker.

`Disk` keeps exactly what a node's `Ready`s handed over; `Machine` is the pure-core state
machine (a counter and bank accounts applied from JSON entries). The store-backed replica of the
commit path is in `mapbench.sim_store`. `Checker` asserts the Raft safety properties (paper
Fig. 3) and that replicas at the same applied index agree, whichever state machine runs.
"""

from __future__ import annotations

import json
import random
from collections.abc import Hashable
from contextlib import AbstractContextManager, nullcontext
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

from mapapi.swarm.raft_types import (
    Entry,
    EntryKind,
    HardState,
    PersistentState,
    RaftOptions,
    Ready,
    Role,
    Snapshot,
)

if TYPE_CHECKING:
    from mapbench.sim import SimNode

TICK = 10
"""Simulated time units per tick."""
ACCOUNTS = 4
"""Bank accounts; each starts with `BALANCE`."""
BALANCE = 100
A0 = 1000
"""The counter's initial value."""
SIM_OPTIONS = RaftOptions(election_tick=10, heartbeat_tick=2, max_inflight=4, max_entries_per_msg=8)
"""The core's tunables in the simulator: small windows, so flow control and paging happen."""


class Violation(AssertionError):
    """A safety or liveness property failed."""


@dataclass
class Faults:
    """How hostile one seed's world is."""

    drop: float
    duplicate: float
    max_delay: int
    defer_ready: float  # chance a node leaves its Ready unprocessed for a while
    fault_every: int  # mean time units between fault events
    slow_disk: float = 0.0  # chance a Ready's write ends later, the node stepping meanwhile


def world(rng: random.Random) -> Faults:
    """Draw how hostile the network and the nodes are, per seed."""
    return Faults(
        drop=rng.choice([0.0, 0.01, 0.05, 0.15]),
        duplicate=rng.choice([0.0, 0.02, 0.1]),
        max_delay=rng.choice([2, 8, 20, 40]),
        defer_ready=rng.choice([0.0, 0.2, 0.5]),
        fault_every=rng.choice([100, 300, 1000]),
    )


class NodeDisk(Protocol):
    """Where a node's Raft state persists: survives a crash, loses nothing it was handed."""

    def save(self, rd: Ready) -> None:
        """Persist a Ready: snapshot, entries, hard state."""

    def save_snapshot(self, snap: Snapshot) -> None:
        """Persist a compaction."""

    def state(self) -> PersistentState:
        """What a restarted node reads back."""


class Replica(Protocol):
    """A node's state machine, driven by the simulator like `RaftGroups` drives a store."""

    applied: int

    def batch(self) -> AbstractContextManager[None]:
        """One transaction around the committed entries of one Ready."""

    def apply(self, entry: Entry) -> object:
        """Apply the next committed entry; what its proposer learns."""

    def install(self, snap: Snapshot) -> None:
        """Replace the state with a snapshot's."""

    def snapshot_data(self) -> bytes:
        """The state at `applied`, as a snapshot payload."""

    def digest(self) -> Hashable:
        """What two replicas at the same applied index must agree on."""

    def check(self) -> None:
        """Local invariants (the bank total); raises `Violation`."""


def step(replica: Replica, entry: Entry) -> bool:
    """Move `replica.applied` to the next committed entry (anything but the next index is
    a gap or a repeat: a `Violation`); whether the entry carries a proposal (NORMAL)."""
    if entry.index != replica.applied + 1:
        raise Violation(f"applied {entry.index} after {replica.applied}: a gap or applied twice")
    replica.applied = entry.index
    return entry.kind is EntryKind.NORMAL


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
    """The pure-core state machine: a counter and bank accounts, rebuilt from snapshots."""

    applied: int = 0
    counter: int = A0
    accounts: list[int] = field(default_factory=lambda: [BALANCE] * ACCOUNTS)
    ops: list[int] = field(default_factory=list)  # op ids applied, in order

    def batch(self) -> AbstractContextManager[None]:
        """Nothing to make atomic in memory."""
        return nullcontext()

    def apply(self, entry: Entry) -> object:
        """Apply one committed entry (NOOP and CONF_CHANGE entries only move `applied`)."""
        if not step(self, entry):
            return None
        op = json.loads(entry.data)
        if op["id"] in self.ops:
            raise Violation(f"op {op['id']} applied twice (index {entry.index})")
        self.ops.append(op["id"])
        if op["op"] == "inc":
            self.counter += op["by"]
        elif self.accounts[op["src"]] >= op["amount"]:
            self.accounts[op["src"]] -= op["amount"]
            self.accounts[op["dst"]] += op["amount"]
        return None

    def install(self, snap: Snapshot) -> None:
        """Take the snapshot's state."""
        other = Machine.decode(snap.data)
        self.applied, self.counter, self.accounts, self.ops = (
            other.applied,
            other.counter,
            other.accounts,
            other.ops,
        )

    def snapshot_data(self) -> bytes:
        """The snapshot payload."""
        return json.dumps([self.applied, self.counter, self.accounts, self.ops]).encode()

    @classmethod
    def decode(cls, data: bytes) -> Machine:
        """A machine from a snapshot payload."""
        if not data:
            return cls()
        applied, counter, accounts, ops = json.loads(data)
        return cls(applied, counter, accounts, ops)

    def digest(self) -> Hashable:
        """What two machines at the same index must agree on."""
        return self.counter, tuple(self.accounts), len(self.ops)

    def check(self) -> None:
        """The bank total never changes."""
        if sum(self.accounts) != ACCOUNTS * BALANCE:
            raise Violation(f"bank total {sum(self.accounts)} at {self.applied}")


class Checker:
    """Safety invariants, checked incrementally after every event (paper Fig. 3)."""

    def __init__(self) -> None:
        self.leaders: dict[int, int] = {}  # term -> leader (Election Safety)
        self.entries: dict[tuple[int, int], tuple[Any, int | None]] = {}  # Log Matching
        self.history: list[Entry] = []  # State Machine Safety: the one applied history
        self.bounds: list[int] = []  # per history entry: the lowest term it was applied at
        self.digests: dict[int, Hashable] = {}

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

    def reloaded(self, node: SimNode, state: PersistentState) -> None:
        """A restarted node's log is what it persisted, and still matches (Log Matching):
        every entry after its snapshot was persisted once, after the same previous term."""
        prev: int | None = state.snapshot.term if state.snapshot.index else 0
        for entry in state.entries:
            seen = self.entries.get((entry.index, entry.term))
            if seen is None or seen[0] != (entry.kind, entry.data):
                raise Violation(f"node {node.id} reloaded {entry}, which it never persisted")
            if None not in (prev, seen[1]) and prev != seen[1]:
                raise Violation(
                    f"node {node.id} reloaded entry {entry.index} of term {entry.term} "
                    f"after term {prev}, not {seen[1]}"
                )
            prev = entry.term

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
        """Replicas at the same index agree; their local invariants hold."""
        replica = node.replica
        try:
            replica.check()
        except Violation as err:
            raise Violation(f"node {node.id}: {err}") from None
        digest = replica.digest()
        known = self.digests.setdefault(replica.applied, digest)
        if known != digest:
            raise Violation(f"node {node.id} at {replica.applied}: state {digest} != {known}")
