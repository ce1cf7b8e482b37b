"""The `Store` protocol: what the core needs from persistence."""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import AbstractContextManager
from dataclasses import dataclass
from typing import Literal, Protocol

from mapapi._pb.mapapi.v1 import core_pb2
from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId

IdKind = Literal["item", "chunk", "commit"]


@dataclass(frozen=True, slots=True)
class ChunkInfo:
    """A chunk known locally: its id, its table, how many live items it holds now
    and their payloads' bytes."""

    id: ChunkId
    table: str
    items: int
    bytes: int = 0


@dataclass(frozen=True, slots=True)
class LogRow:
    """One stored Raft log entry of a chunk's group (kind: the entry kind's number)."""

    index: int
    term: int
    kind: int
    data: bytes


@dataclass(frozen=True, slots=True)
class TxRow:
    """What a chunk's log recorded of a transaction over several chunks: `state`
    is "prepared" (its writes wait, encoded in `data`, reserving `time`),
    "committed" (at `time`) or "aborted"."""

    state: str
    time: int
    data: bytes = b""


@dataclass(frozen=True, slots=True)
class Divergence:
    """Another holder's hash chain of a chunk differs from this replica's at
    `position` (the commit's number in the chain, from 1): one of the two holds
    another history (issue 18 §3; `swarm/chain_watch.py`)."""

    chunk: ChunkId
    peer: PeerId
    position: int
    detail: str
    noticed: float  # seconds since the epoch


@dataclass(frozen=True, slots=True)
class Rollback:
    """The store holds fewer commits than it had recorded holding (its
    high-water mark, `store/mark.py`): `recorded` commit records once, `stored`
    when it was found; `noticed` is when a write found it (0: found now)."""

    recorded: int
    stored: int
    commit: str  # the newest commit the mark named
    noticed: float = 0.0

    @property
    def missing(self) -> int:
        """How many commit records the store lost."""
        return self.recorded - self.stored


@dataclass(frozen=True, slots=True)
class RaftRecord:
    """What a chunk's Raft group persisted here: hard state, applied index, the
    last snapshot (index, term, config, data), the log after it, and the newest
    commit time applied from the log (the chunk's clock)."""

    term: int
    vote: int
    commit: int
    applied: int
    snap_index: int
    snap_term: int
    snap_config: bytes
    snap_data: bytes
    entries: tuple[LogRow, ...]
    time: int = 0


class Store(Protocol):
    """Tables, chunks, full item history, commit records and persisted views.

    All reads of revisions take a logical time; writes of revisions happen only
    through `apply_commit`, which is atomic (all of the commit or none of it).
    """

    def close(self) -> None:
        """Release files and connections."""

    def clock(self) -> int:
        """The highest commit time applied so far (0 when empty)."""

    def exclusive(self) -> AbstractContextManager[None]:
        """Serialise committers: while held, no other writer (thread or process)
        can apply a commit, so validation and `apply_commit` are atomic together."""

    # tables and chunks
    def add_table(self, name: str, type_name: str, replication: int = 0) -> None:
        """Register a table, whose chunks have the replication factor `replication`
        unless given their own (0: the swarm's default); raises UsageError if the
        name is taken."""

    def tables(self) -> dict[str, str]:
        """Table name -> full protobuf type name."""

    def add_chunk(self, chunk_id: ChunkId, table: str, replication: int = 0) -> None:
        """Register a chunk of `table` (which must exist), with the replication factor
        `replication` (0: its table's); a known chunk keeps its own."""

    def chunks(self, table: str | None = None, only: ChunkId | None = None) -> list[ChunkInfo]:
        """The chunks held here, optionally of one table, or just `only` (counting a
        chunk's items reads all its revisions: count only the ones asked about)."""

    def chunk_ids(self, table: str | None = None) -> list[ChunkId]:
        """The ids of `chunks(table)`, in order, without counting their items
        (which reads every revision)."""

    def chunk_table(self, chunk_id: ChunkId) -> str:
        """The table of a chunk; raises ChunkNotFound."""

    def replication(self, chunk_id: ChunkId) -> int:
        """The chunk's replication factor, the most voters its Raft group has (0: the
        swarm's default); set when the chunk is made (else its table's), and carried
        to every holder with its state. Raises ChunkNotFound."""

    def set_replication(self, chunk_id: ChunkId, factor: int) -> None:
        """Set the chunk's replication factor (as its holders have it)."""

    # revisions
    def read(self, item_id: ItemId, time: int) -> Revision | None:
        """The newest revision at or before `time`, tombstones included."""

    def history(self, item_id: ItemId) -> list[Revision]:
        """Every revision of an item, oldest first."""

    def scan(
        self, time: int, *, table: str | None = None, chunk: ChunkId | None = None
    ) -> list[Revision]:
        """The items visible at `time` (not removed), in a table or chunk."""

    def latest(self, item_ids: Sequence[ItemId]) -> dict[ItemId, Revision]:
        """The newest revision of each existing item among `item_ids`."""

    def changed_since(
        self, time: int, *, table: str | None = None, chunk: ChunkId | None = None
    ) -> list[Revision]:
        """Revisions written after `time`, in a table or chunk, oldest first."""

    # commits
    def apply_commit(self, record: CommitRecord, revisions: Sequence[Revision]) -> None:
        """Write a commit's revisions and record atomically; advances `clock()`.

        In the same transaction it extends the hash chain (`core/chain.py`) of
        each chunk whose part of the commit it writes for the first time: every
        commit path (a lone peer's, a writer's and a holder's in the swarm, a
        chunk's log) goes through here, so every replica links every commit."""

    def commits(self, limit: int | None = None) -> list[CommitRecord]:
        """Commit records, newest first."""

    def commit_record(self, commit_id: CommitId) -> CommitRecord | None:
        """One commit record, or None."""

    def commit_revisions(self, commit_id: CommitId) -> list[Revision]:
        """The revisions one commit wrote."""

    def resolve_prefix(self, kind: IdKind, prefix: str) -> list[str]:
        """Ids of `kind` starting with `prefix` (at most 2: enough to see ambiguity)."""

    # persisted CLI views
    def history_floor(self) -> int:
        """The earliest time every revision is still stored for: `mapctl gc`
        dropped revisions only earlier reads see (0: the history is whole)."""

    def load_view(self, name: str) -> bytes | None:
        """The serialized view `name`, or None."""

    def save_view(self, name: str, blob: bytes) -> None:
        """Create or replace a view."""

    def delete_view(self, name: str) -> None:
        """Forget a view (no error if absent)."""

    def views(self) -> dict[str, bytes]:
        """Every view by name."""


class ReplicaStore(Store, Protocol):
    """What replication needs on top of `Store` (both stores provide it)."""

    def holders(self, chunk_id: ChunkId) -> list[PeerId]:
        """The peers that hold a chunk, in id order."""

    def holdings(self) -> dict[ChunkId, list[PeerId]]:
        """Every chunk's holders, in id order (chunks with a recorded holder set)."""

    def set_holders(self, chunk_id: ChunkId, peers: Sequence[PeerId]) -> None:
        """Replace a chunk's holder set."""

    def chunk_revisions(self, chunk_id: ChunkId) -> list[Revision]:
        """The full history of a chunk's items."""

    def chunk_revisions_pb(self, chunk_id: ChunkId) -> list[core_pb2.Revision]:
        """`chunk_revisions` as wire messages (what a Raft snapshot carries)."""

    def chunk_commits(self, chunk_id: ChunkId) -> list[CommitRecord]:
        """Records of the commits that wrote to a chunk, oldest first."""

    def item_chunk(self, item_id: ItemId) -> ChunkId | None:
        """The chunk an item belongs to, if known here."""

    def install_chunk(
        self,
        chunk_id: ChunkId,
        table: str,
        type_name: str,
        revisions: Sequence[Revision],
        commits: Sequence[CommitRecord],
        holders: Sequence[PeerId],
        base: Sequence[tuple[CommitId, bytes]] = (),
    ) -> None:
        """Take in a replica received from a holder, atomically; `base` is the
        holder's compacted chain (`chain_base`)."""

    def drop_chunk(self, chunk_id: ChunkId) -> None:
        """Forget a chunk's replica (commit records stay)."""

    # -- the Raft group of each chunk (DESIGN §13) -------------------------------------
    def raft_load(self, chunk_id: ChunkId) -> RaftRecord | None:
        """The persisted state of the chunk's group, or None if there is none."""

    def raft_save(
        self,
        chunk_id: ChunkId,
        *,
        hard: tuple[int, int, int] | None = None,
        entries: Sequence[LogRow] = (),
        snapshot: tuple[int, int, bytes, bytes] | None = None,
        compacted: bool = False,
    ) -> None:
        """Persist a snapshot (it replaces the whole stored log), then entries
        (replacing the log from the first one's index on), then the hard state
        (term, vote, commit), atomically. A `compacted` snapshot (this replica's
        own, at an applied index) replaces only the entries up to its index, and
        only if newer than the stored one."""

    def raft_applied(self, chunk_id: ChunkId, index: int, time: int = 0) -> None:
        """Record the applied index and the newest commit time it brought; inside
        `exclusive()` with the entry's effect, so both land or neither does.

        Raises:
            ValueError: the index goes backwards.
        """

    def raft_applied_index(self, chunk_id: ChunkId) -> int | None:
        """The chunk's applied log index, or None if it has no Raft group: cheap
        (`raft_load` reads the whole log)."""

    def raft_time(self, chunk_id: ChunkId) -> int:
        """The newest commit time applied from the chunk's log (0 if none)."""

    def integrity(self) -> list[str]:
        """What is wrong with the store's own structure (empty: nothing found)."""

    def chain_link(self, chunk_id: ChunkId, commit_id: CommitId, link: bytes) -> None:
        """Append a commit's link to the chunk's hash chain (inside `exclusive()`,
        with the commit it stands for), unless the chain's head links that
        commit already (`apply_commit` linked it)."""

    def chain_head(self, chunk_id: ChunkId) -> bytes | None:
        """The chunk's newest link, or None before its first commit through the log."""

    def chain_links(self, chunk_id: ChunkId) -> list[tuple[CommitId, bytes]]:
        """Every (commit, link) of the chunk's chain, oldest first."""

    def chain_at(self, chunk_id: ChunkId, seq: int) -> bytes | None:
        """The link of the chunk's `seq`-th commit (from 1), or None if it has fewer."""

    def chain_base(self, chunk_id: ChunkId) -> list[tuple[CommitId, bytes]]:
        """The chain's compacted links (`mapctl gc`), oldest first; empty when
        the chunk's history is whole."""

    def chain_length(self, chunk_id: ChunkId) -> int:
        """How many commits the chunk's chain links."""

    def diverged(self, found: Divergence) -> None:
        """Record that a holder's chain differs from this replica's (kept until a
        comparison with that holder agrees past it, or the chunk is fetched anew)."""

    def agreed(self, chunk_id: ChunkId, peer: PeerId, position: int) -> None:
        """Forget a divergence from `peer` at or before `position` of the chunk's
        chain: the two chains agree up to there now."""

    def divergences(self) -> list[Divergence]:
        """Every recorded divergence, by chunk and peer."""

    def rollbacks(self) -> list[Rollback]:
        """How the store fell behind its own high-water mark: each rollback a write
        found (and recorded), then one found now; empty when it never did."""

    def accept_rollback(self) -> None:
        """Forget the recorded rollbacks and mark the store as it is now."""

    def raft_tx(self, chunk_id: ChunkId, commit_id: CommitId) -> TxRow | None:
        """What the chunk's log recorded of a multi-chunk transaction, or None."""

    def raft_tx_put(self, chunk_id: ChunkId, commit_id: CommitId, row: TxRow) -> None:
        """Record what the chunk's log did with a transaction (inside `exclusive()`,
        with the entry's applied index)."""

    def raft_tx_prepared(self, chunk_id: ChunkId) -> list[tuple[CommitId, TxRow]]:
        """The transactions prepared on the chunk and not decided there yet."""

    def raft_txs(self, chunk_id: ChunkId) -> list[tuple[CommitId, TxRow]]:
        """Every transaction the chunk's log recorded, prepared or decided."""

    def raft_drop(self, chunk_id: ChunkId) -> None:
        """Forget the chunk's group state."""


def newest_first(records: Iterator[CommitRecord] | list[CommitRecord]) -> list[CommitRecord]:
    """Commit records sorted newest first (ties by id, for a stable order)."""
    return sorted(records, key=lambda c: (c.time, c.id), reverse=True)
