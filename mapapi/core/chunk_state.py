"""A chunk's whole state as one value (DESIGN §13): what a Raft snapshot carries to
a holder that joins the chunk's group, or lags behind its compacted log. Pure data;
`core/codec.py` serializes it, `swarm/chunk_state.py` takes it from and installs it
into a store.
"""

from __future__ import annotations

from dataclasses import dataclass

from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import CommitId


@dataclass(frozen=True, slots=True)
class TxState:
    """What the chunk's log recorded of one multi-chunk transaction (`Store.raft_tx`)."""

    commit_id: CommitId
    state: str
    time: int
    data: bytes = b""


@dataclass(frozen=True, slots=True)
class ChunkState:
    """A chunk's table, clock, whole history (since its last `gc`), transaction
    records, replication factor (0: the swarm's default) and the compacted part
    of its hash chain."""

    table: str
    type_name: str
    time: int
    revisions: tuple[Revision, ...]
    commits: tuple[CommitRecord, ...]
    txs: tuple[TxState, ...] = ()
    replication: int = 0
    compacted: tuple[tuple[CommitId, bytes], ...] = ()  # the chain's part `gc` left bare
