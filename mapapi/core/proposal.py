"""A transaction as proposed to a chunk's Raft group (DESIGN §13): pure data.

Everything a holder needs to validate and apply the transaction in log order,
the same way on every holder: the write set, the begin time (and, per item the
transaction committed before, the time after which a foreign write conflicts),
the read set and scanned scopes under serializable isolation, and the commit's
metadata. The proposer's Lamport time is a floor: holders stamp the commit at
the chunk's next time if that is later (`swarm/apply.py`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId
from mapapi.core.transaction import Change, Isolation, Transaction
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

    def since_of(self, item_id: ItemId) -> int:
        """The time after which a foreign write to `item_id` conflicts."""
        return self.since.get(item_id, self.begin_time)

    @classmethod
    def of(cls, tx: Transaction, chunk: ChunkId, message: str, time: int) -> Proposal:
        """The part of `tx` that writes to `chunk`, proposed at Lamport `time`."""
        changes = tuple(c for c in tx.changes if c.chunk_id == chunk)
        since = {c.item_id: tx.since(c.item_id) for c in changes}
        return cls(
            CommitId.new(),
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
        )
