"""A transaction as proposed to a chunk's Raft group (DESIGN §13): pure data.

Everything a holder needs to validate and apply the transaction in log order,
the same way on every holder: the write set, the begin time (and, per item the
transaction committed before, the time after which a foreign write conflicts),
the read set and scanned scopes under serializable isolation, and the commit's
metadata. The proposer's Lamport time is a floor: holders stamp the commit at
the chunk's next time if that is later (`swarm/apply.py`).

A transaction over several chunks is proposed to each chunk as a prepare (a
proposal naming its `participants`) and then ended by a `TxDecision` in each
chunk's log (two-phase commit, `swarm/two_phase.py`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from mapapi.core.change import Change
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId
from mapapi.core.transaction import Isolation, Transaction
from mapapi.core.view import Scope


@dataclass(frozen=True, slots=True)
class Proposal:
    """One transaction's writes to one chunk, and what they must be checked against."""

    commit_id: CommitId
    time: int
    author: PeerId
    author_name: str
    view: str
    message: str
    begin_time: int
    isolation: Isolation
    changes: tuple[Change, ...]
    since: Mapping[ItemId, int] = field(default_factory=dict)
    read_set: frozenset[ItemId] = frozenset()
    scopes: frozenset[Scope] = frozenset()
    participants: tuple[ChunkId, ...] = ()
    """Every chunk of a multi-chunk transaction, in id order (empty: one chunk): those
    it writes and, under serializable isolation, those whose reads it validates."""

    @property
    def is_prepare(self) -> bool:
        """Whether this is one chunk's prepare of a transaction over several."""
        return bool(self.participants)

    def since_of(self, item_id: ItemId) -> int:
        """The time after which a foreign write to `item_id` conflicts."""
        return self.since.get(item_id, self.begin_time)

    @classmethod
    def of(
        cls,
        tx: Transaction,
        chunk: ChunkId,
        message: str,
        time: int,
        participants: tuple[ChunkId, ...] = (),
        commit_id: CommitId | None = None,
    ) -> Proposal:
        """The part of `tx` that writes to `chunk`, proposed at Lamport `time` (a
        prepare if `participants` names the transaction's chunks; they share
        `commit_id`)."""
        changes = tuple(c for c in tx.changes if c.chunk_id == chunk)
        since = {c.item_id: tx.since(c.item_id) for c in changes}
        return cls(
            commit_id or CommitId.new(),
            time,
            tx.author,
            tx.author_name,
            tx.view,
            message,
            tx.begin_time,
            tx.isolation,
            changes,
            {i: t for i, t in since.items() if t != tx.begin_time},
            frozenset(tx.read_set) if tx.isolation == "serializable" else frozenset(),
            frozenset(tx.scopes) if tx.isolation == "serializable" else frozenset(),
            participants,
        )


@dataclass(frozen=True, slots=True)
class TxDecision:
    """How a transaction over several chunks ended: committed at `time` on every
    chunk it writes, or aborted (`time` 0). A chunk's log keeps the first decision
    it applies for a transaction; later ones change nothing."""

    commit_id: CommitId
    commit: bool
    time: int = 0


@dataclass(frozen=True, slots=True)
class TimeFloor:
    """A reader closes a chunk's log up to `time`: applying it moves the chunk's clock
    there, so every commit applied after it is stamped later (`swarm/apply.py`), and a
    view reading the chunk at `time` once the floor applied reads a state that never
    changes."""

    time: int


LogEntry = Proposal | TxDecision | TimeFloor
"""What a chunk's log entry carries."""
