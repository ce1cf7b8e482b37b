"""`Peer`: the async public facade; composes the store, clock and commit path.

This is the single-peer core; it holds no protocol logic of its own and
delegates to `commit`, `transaction` and the store.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from mapapi.clock import LamportClock
from mapapi.commit import commit_locally
from mapapi.errors import UsageError
from mapapi.history import CommitRecord, Revision
from mapapi.ids import ChunkId, CommitId, ItemId, PeerId
from mapapi.repo import Repository
from mapapi.store import ChunkInfo, MemoryStore, Store
from mapapi.table import TableDescriptor
from mapapi.transaction import Change, Isolation, Transaction

if TYPE_CHECKING:
    from google.protobuf.message import Message

    from mapapi.merge import MergePolicy


class Peer:
    """One peer and its local map repository."""

    def __init__(self, store: Store, peer_id: PeerId | None = None, *, name: str = "") -> None:
        self.store = store
        self.id = peer_id or PeerId.new()
        self.name = name or self.id.short
        self.clock = LamportClock(store.clock())
        self._descriptors: dict[str, TableDescriptor] = {}
        self._policies: dict[str, MergePolicy] = {}

    @classmethod
    def open(cls, path: str | Path = ".") -> Peer:
        """The peer of the repository at (or above) `path`."""
        repo = Repository.find(path)
        return cls(repo.open_store(), repo.config.peer_id, name=repo.config.name)

    @classmethod
    def in_memory(cls) -> Peer:
        """A scratch peer on a `MemoryStore`."""
        return cls(MemoryStore())

    async def close(self) -> None:
        """Release the store."""
        self.store.close()

    async def __aenter__(self) -> Peer:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    # -- tables and chunks --------------------------------------------------
    async def create_table(self, name: str, message_type: str | type[Message]) -> TableDescriptor:
        """Create a table of `message_type` (a class or a full protobuf name)."""
        if not name or not name.replace("_", "").replace("-", "").replace(".", "").isalnum():
            raise UsageError(f"bad table name {name!r}: use letters, digits, '_', '-', '.'")
        if isinstance(message_type, str):
            descriptor = TableDescriptor.named(name, message_type)
        else:
            descriptor = TableDescriptor(name, message_type)
        self.store.add_table(name, descriptor.type_name)
        self._descriptors[name] = descriptor
        return descriptor

    def tables(self) -> dict[str, TableDescriptor]:
        """Every table of the repository."""
        return {name: self.table(name) for name in self.store.tables()}

    def table(self, name: str) -> TableDescriptor:
        """One table's descriptor."""
        descriptor = self._descriptors.get(name)
        if descriptor is None:
            type_name = self.store.tables().get(name)
            if type_name is None:
                raise UsageError(f"no table {name!r}; create it with `mapctl table create`")
            descriptor = self._descriptors[name] = TableDescriptor.named(name, type_name)
        return descriptor

    async def create_chunk(self, table: str) -> ChunkId:
        """A new, empty chunk of `table`, held by this peer."""
        self.table(table)
        chunk_id = ChunkId.new()
        self.store.add_chunk(chunk_id, table)
        return chunk_id

    def chunks(self, table: str | None = None) -> list[ChunkInfo]:
        """The chunks this peer holds."""
        if table is not None:
            self.table(table)
        return self.store.chunks(table)

    def chunk_table(self, chunk_id: ChunkId) -> str:
        """The table of a chunk held here."""
        return self.store.chunk_table(chunk_id)

    def set_merge_policy(self, table: str, policy: MergePolicy | None) -> None:
        """Install (or with None, remove) the auto-merge policy of a table."""
        self.table(table)
        if policy is None:
            self._policies.pop(table, None)
        else:
            self._policies[table] = policy

    # -- transactions ---------------------------------------------------------
    def now(self) -> int:
        """The newest time whose commits are all applied here."""
        time = self.store.clock()
        self.clock.advance_to(time)
        return time

    def begin(self, at: int | None = None, *, isolation: Isolation = "snapshot") -> Transaction:
        """A transaction reading the map as of now (or of logical time `at`)."""
        now = self.now()
        if at is not None and not 0 <= at <= now:
            raise UsageError(f"time {at} is outside 0..{now} (the newest commit time)")
        return Transaction(self, now if at is None else at, self.id, isolation=isolation)

    def read_local(self, item_id: ItemId, time: int) -> Revision | None:
        """The newest local revision of an item at or before `time`."""
        return self.store.read(item_id, time)

    async def read(self, item_id: ItemId, time: int) -> Revision | None:
        """Like `read_local` (one peer holds every chunk)."""
        return self.store.read(item_id, time)

    async def scan(self, time: int, table: str, chunk: ChunkId | None) -> list[Revision]:
        """Items visible at `time` in a table or chunk."""
        return self.store.scan(time, table=table, chunk=chunk)

    async def commit_transaction(self, tx: Transaction, message: str) -> CommitRecord | None:
        """Validate and apply a transaction (see `mapapi.commit`)."""
        return commit_locally(self.store, tx, message, self.clock, self._try_merge)

    def _try_merge(self, ours: Change, theirs: Revision, base: Revision | None) -> bytes | None:
        policy = self._policies.get(ours.table)
        if policy is None:
            return None
        descriptor = self.table(ours.table)
        merged = policy(
            None if base is None or base.removed else descriptor.decode(base.data),
            descriptor.decode(ours.data),
            descriptor.decode(theirs.data),
        )
        return None if merged is None else descriptor.encode(merged)

    # -- history -------------------------------------------------------------
    def log(self, limit: int | None = None) -> list[CommitRecord]:
        """Commit records, newest first."""
        return self.store.commits(limit)

    def history(self, item_id: ItemId) -> list[Revision]:
        """Every revision of an item, oldest first."""
        return self.store.history(item_id)

    def commit_record(self, commit_id: CommitId) -> CommitRecord | None:
        """One commit record."""
        return self.store.commit_record(commit_id)

    def commit_revisions(self, commit_id: CommitId) -> list[Revision]:
        """The revisions one commit wrote."""
        return self.store.commit_revisions(commit_id)
