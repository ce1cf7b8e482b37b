"""Transactions: views at a begin time with optimistic commits (DESIGN §5).

A `Transaction` reads the map as it was at its begin time, buffers its own changes (which its
reads see), and commits them atomically through its backend. Validation itself is the pure
function `core.validate.validate`: an updated or removed item conflicts if someone else wrote
it after the begin time (or after this transaction's own earlier commit of it); an insert
conflicts if the id exists; with `isolation="serializable"` the read set is validated too."""

from __future__ import annotations

from collections.abc import Iterable
from enum import Enum
from typing import TYPE_CHECKING, Any, Literal, Protocol

from mapapi.core.change import Change, Op
from mapapi.core.errors import ConflictError, ItemNotFound, UsageError, ViewClosedError
from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, ItemId, PeerId

if TYPE_CHECKING:
    from google.protobuf.message import Message

    from mapapi.core.table import TableDescriptor

Isolation = Literal["snapshot", "serializable"]
ISOLATIONS: tuple[Isolation, ...] = ("snapshot", "serializable")


class TransactionBackend(Protocol):
    """What a transaction needs from the peer it runs on."""

    def table(self, name: str) -> TableDescriptor:
        """The descriptor of a table; raises UsageError if unknown."""

    def chunk_table(self, chunk_id: ChunkId) -> str:
        """The table a chunk belongs to; raises ChunkNotFound."""

    def read_local(self, item_id: ItemId, time: int) -> Revision | None:
        """The newest local revision at or before `time` (no network)."""

    async def read(self, item_id: ItemId, time: int) -> Revision | None:
        """Like `read_local`, fetching the item's chunk first where needed."""

    async def scan(self, time: int, table: str, chunk: ChunkId | None) -> list[Revision]:
        """Items visible at `time` in a table or one of its chunks."""

    async def catch_up(
        self,
        time: int,
        *,
        item: ItemId | None = None,
        table: str = "",
        chunk: ChunkId | None = None,
    ) -> int:
        """Before the first read of a view begun now (at `time`): bring what that
        read touches (`item`'s chunk, else `chunk`, else every chunk of `table`)
        up to date, and return the time the view reads at from then on: `time`,
        or later, as if the view had begun once they were up to date."""

    async def commit_transaction(self, tx: Transaction, message: str) -> CommitRecord | None:
        """Validate and apply `tx`'s changes; raises ConflictError."""

    @property
    def name(self) -> str:
        """The peer's name (`init --name`), stamped on its commits."""


class TxState(Enum):
    """Where a transaction is in its life (not the protobuf `ViewState`, a persisted CLI view)."""

    OPEN = 1
    VALIDATING = 2
    CONFLICTED = 3
    ABORTED = 4


_ALLOWED = {
    TxState.OPEN: {TxState.VALIDATING, TxState.ABORTED},
    TxState.VALIDATING: {TxState.OPEN, TxState.CONFLICTED},
    TxState.CONFLICTED: {TxState.ABORTED},
}


class Transaction:
    """A view of the map at `begin_time` plus buffered changes.

    Reads are coroutines because reading a chunk this peer does not hold
    fetches it first; writes only buffer. `commit()` may be called more than
    once: the begin time stays, and the transaction's own earlier commits are
    never conflicts for it (multi-commit).
    """

    def __init__(
        self,
        backend: TransactionBackend,
        begin_time: int,
        author: PeerId,
        *,
        isolation: Isolation = "snapshot",
        view: str = "",
        fresh: bool = False,
    ) -> None:
        if isolation not in ISOLATIONS:
            raise UsageError(f"isolation must be one of {ISOLATIONS}, not {isolation!r}")
        self._backend = backend
        self.begin_time = begin_time
        self.author = author
        self.author_name = backend.name
        self.view = view  # the named view this transaction stands for, if any
        self.isolation: Isolation = isolation
        self.state = TxState.OPEN
        self._changes: dict[ItemId, Change] = {}
        self._own: dict[ItemId, Revision] = {}  # revisions of our earlier commits
        self._seen: dict[ItemId, int] = {}  # item -> the version's time when first written
        self._read_set: set[ItemId] = set()
        self._scopes: set[tuple[str, ChunkId | None]] = set()
        # Begun "now" and nothing read, written or committed yet: the first read may
        # move the begin time forward (`_first_read`).
        self._fresh = fresh

    # -- state -------------------------------------------------------------
    def _transition_to(self, target: TxState) -> None:
        if target not in _ALLOWED.get(self.state, set()):
            raise ViewClosedError(
                f"transaction cannot go {self.state.name} -> {target.name}"
                + ("; use err.merge() for a new one" if self.state is TxState.CONFLICTED else "")
            )
        self.state = target

    def _check_open(self) -> None:
        if self.state is not TxState.OPEN:
            raise ViewClosedError(f"transaction is {self.state.name}, not OPEN")

    def _writing(self) -> None:
        """A write begins: the transaction must be open, and is no longer fresh
        (a written view keeps its begin time)."""
        self._check_open()
        self._fresh = False

    @property
    def changes(self) -> list[Change]:
        """The buffered changes, in the order first made."""
        return list(self._changes.values())

    @property
    def read_set(self) -> set[ItemId]:
        """Items read by `get` (validated under serializable isolation)."""
        return set(self._read_set)

    @property
    def scopes(self) -> set[tuple[str, ChunkId | None]]:
        """(table, chunk or None) ranges scanned by `items`/`find`."""
        return set(self._scopes)

    def note_reads(
        self, read_set: Iterable[ItemId], scopes: Iterable[tuple[str, ChunkId | None]]
    ) -> None:
        """Count reads made elsewhere (an earlier command of a CLI view) as ours."""
        self._read_set.update(read_set)
        self._scopes.update(scopes)

    def since(self, item_id: ItemId) -> int:
        """The time after which a foreign write to `item_id` conflicts with us: our
        own last commit of it, else the version this replica showed when we first
        wrote it (if older than the begin time), else the begin time."""
        own = self._own.get(item_id)
        if own is not None:
            return own.update_time
        return min(self._seen.get(item_id, self.begin_time), self.begin_time)

    def _saw(self, item_id: ItemId) -> None:
        """Note, the first time we write `item_id`, which version of it this replica
        shows at the begin time: a commit that lands on it afterwards is a conflict
        even if its time is not past the begin time (in a swarm, times are Lamport
        times, and a writer elsewhere may stamp a commit below ours)."""
        if item_id not in self._seen and item_id not in self._own:
            revision = self._backend.read_local(item_id, self.begin_time)
            if revision is not None:
                self._seen[item_id] = revision.update_time

    # -- reads ---------------------------------------------------------------
    async def _first_read(
        self, *, item: ItemId | None = None, table: str = "", chunk: ChunkId | None = None
    ) -> None:
        """Before the first read of a fresh view, let the backend bring what it reads
        up to date, and move the begin time to the time it answers: the same as
        having begun a moment later, so commits acknowledged elsewhere before the
        view's first read are seen (in a swarm, a commit returns once a majority of
        holders took it, and Lamport times do not order real time across peers).
        A view that has read or written already stays at its time."""
        if not self._fresh:
            return
        self._fresh = False
        moved = await self._backend.catch_up(self.begin_time, item=item, table=table, chunk=chunk)
        self.begin_time = max(self.begin_time, moved)

    def _overlay(self, item_id: ItemId) -> tuple[bool, bytes | None]:
        """(known, data) from our own buffer or earlier commits."""
        change = self._changes.get(item_id)
        if change is not None:
            return True, None if change.op is Op.REMOVE else change.data
        own = self._own.get(item_id)
        if own is not None:
            return True, None if own.removed else own.data
        return False, None

    async def get(self, table: str, item_id: ItemId) -> Message | None:
        """The item as this transaction sees it, or None if absent or removed."""
        descriptor = self._backend.table(table)
        self._read_set.add(item_id)
        known, data = self._overlay(item_id)
        if not known:
            await self._first_read(item=item_id)
            revision = await self._backend.read(item_id, self.begin_time)
            if revision is None or revision.removed:
                return None
            if revision.table != table:
                raise UsageError(
                    f"item {item_id} belongs to table {revision.table!r}, not {table!r}"
                )
            data = revision.data
        return None if data is None else descriptor.decode(data)

    async def items(self, table: str, chunk: ChunkId | None = None) -> dict[ItemId, Message]:
        """Every item of a table (or one of its chunks) this transaction sees."""
        descriptor = self._backend.table(table)
        return {i: descriptor.decode(d) for i, d in (await self.payloads(table, chunk)).items()}

    async def payloads(self, table: str, chunk: ChunkId | None = None) -> dict[ItemId, bytes]:
        """`items`, still serialized, in id order (to decode many off the event loop)."""
        self._backend.table(table)  # an unknown table: UsageError
        if chunk is not None and self._backend.chunk_table(chunk) != table:
            raise UsageError(f"chunk {chunk} does not belong to table {table!r}")
        self._scopes.add((table, chunk))
        await self._first_read(table=table, chunk=chunk)
        found: dict[ItemId, bytes] = {
            r.item_id: r.data for r in await self._backend.scan(self.begin_time, table, chunk)
        }
        overlay: list[tuple[ItemId, str, ChunkId, bytes | None]] = [
            (i, r.table, r.chunk_id, None if r.removed else r.data) for i, r in self._own.items()
        ] + [
            (i, c.table, c.chunk_id, None if c.op is Op.REMOVE else c.data)
            for i, c in self._changes.items()
        ]
        for item_id, item_table, item_chunk, data in overlay:
            if item_table != table or (chunk is not None and item_chunk != chunk):
                continue
            if data is None:
                found.pop(item_id, None)
            else:
                found[item_id] = data
        return dict(sorted(found.items()))

    async def find(
        self, table: str, field: str, value: Any, chunk: ChunkId | None = None
    ) -> dict[ItemId, Message]:
        """Items whose `field` equals `value` (compared in the JSON mapping)."""
        descriptor = self._backend.table(table)
        wanted = descriptor.canonical_json(value)
        return {
            i: m
            for i, m in (await self.items(table, chunk)).items()
            if descriptor.field_json(m, field) == wanted
        }

    # -- writes --------------------------------------------------------------
    def _current_chunk(self, table: str, item_id: ItemId) -> ChunkId:
        """The chunk of an item this transaction sees; raises ItemNotFound."""
        change = self._changes.get(item_id)
        if change is not None and change.op is not Op.REMOVE:
            return change.chunk_id
        if change is None:
            own = self._own.get(item_id)
            revision = own or self._backend.read_local(item_id, self.begin_time)
            if revision is not None and not revision.removed:
                if revision.table != table:
                    raise UsageError(
                        f"item {item_id} belongs to table {revision.table!r}, not {table!r}"
                    )
                return revision.chunk_id
        raise ItemNotFound(f"no item {item_id} in table {table!r} at time {self.begin_time}")

    def _insertable(self, table: str, chunk: ChunkId) -> TableDescriptor:
        """The table's descriptor, once the transaction is open and `chunk` is `table`'s."""
        self._writing()
        descriptor = self._backend.table(table)
        if self._backend.chunk_table(chunk) != table:
            raise UsageError(f"chunk {chunk} does not belong to table {table!r}")
        return descriptor

    def insert(
        self, table: str, message: Message, chunk: ChunkId, item_id: ItemId | None = None
    ) -> ItemId:
        """Buffer a new item in `chunk`; returns its (new random) id."""
        descriptor = self._insertable(table, chunk)
        item_id = item_id or ItemId.new()
        if item_id in self._changes:
            raise UsageError(f"item {item_id} is already changed in this transaction")
        self._changes[item_id] = Change(
            Op.INSERT, table, item_id, chunk, descriptor.encode(message)
        )
        return item_id

    def insert_many(self, table: str, messages: Iterable[Message], chunk: ChunkId) -> list[ItemId]:
        """Buffer new items in `chunk` (checked once, not per item, which is what
        makes bulk imports fast); returns their new random ids."""
        descriptor = self._insertable(table, chunk)
        ids = []
        for message in messages:
            item_id = ItemId.new()
            self._changes[item_id] = Change(
                Op.INSERT, table, item_id, chunk, descriptor.encode(message)
            )
            ids.append(item_id)
        return ids

    def update(self, table: str, item_id: ItemId, message: Message) -> None:
        """Buffer a new version of an existing item."""
        self._writing()
        data = self._backend.table(table).encode(message)
        chunk = self._current_chunk(table, item_id)
        self._saw(item_id)
        previous = self._changes.get(item_id)
        op = Op.INSERT if previous is not None and previous.op is Op.INSERT else Op.UPDATE
        self._changes[item_id] = Change(op, table, item_id, chunk, data)

    def remove(self, table: str, item_id: ItemId) -> None:
        """Buffer the removal of an item (a tombstone revision at commit)."""
        self._writing()
        chunk = self._current_chunk(table, item_id)
        self._saw(item_id)
        previous = self._changes.get(item_id)
        if previous is not None and previous.op is Op.INSERT:
            del self._changes[item_id]  # inserted and removed: nothing to write
            return
        self._changes[item_id] = Change(Op.REMOVE, table, item_id, chunk)

    def stage(self, change: Change) -> None:
        """Buffer a prepared change as is (used to re-apply our side of a conflict)."""
        self._writing()
        self._backend.table(change.table)
        if change.op is not Op.INSERT:
            self._saw(change.item_id)
        self._changes[change.item_id] = change

    def unstage(self, item_id: ItemId) -> None:
        """Drop the buffered change of one item."""
        self._writing()
        self._changes.pop(item_id, None)

    # -- commit ----------------------------------------------------------------
    async def commit(self, message: str = "") -> CommitRecord | None:
        """Validate and apply the buffered changes atomically.

        Returns:
            The commit record, or None when there was nothing to write (a
            serializable transaction still validates its reads then).

        Raises:
            ConflictError: someone changed an item of the write set (or, under
                serializable isolation, the read set) since the begin time; the
                transaction is CONFLICTED and `err.merge()` continues.
        """
        self._transition_to(TxState.VALIDATING)
        try:
            record = await self._backend.commit_transaction(self, message)
        except ConflictError:
            self.state = TxState.CONFLICTED
            raise
        except BaseException:
            self.state = TxState.OPEN  # e.g. a lock timeout: the caller may retry
            raise
        self.state = TxState.OPEN
        return record

    def committed(self, revisions: Iterable[Revision]) -> None:
        """Called by the backend once `revisions` are applied: clear the buffer
        and remember them so later reads and commits of this transaction see them."""
        for revision in revisions:
            self._own[revision.item_id] = revision
        self._changes.clear()
        self._fresh = False

    def abort(self) -> None:
        """Drop the buffered changes; the transaction cannot be used again."""
        self._transition_to(TxState.ABORTED)
        self._changes.clear()

    def merged(self, error: ConflictError) -> Transaction:
        """See `ConflictError.merge`."""
        tx = Transaction(
            self._backend, error.seen_at, self.author, isolation=self.isolation, view=self.view
        )
        conflicting = {c.item_id for c in error.conflicts}
        for item_id, change in self._changes.items():
            if item_id not in conflicting:
                tx._changes[item_id] = change
        if self.state is TxState.CONFLICTED:
            self._transition_to(TxState.ABORTED)
        return tx
