"""The operations `mapctl` performs, as JSON in and JSON out: one table of them.

An `Operations` object maps each operation's name to a coroutine of one of the
operation sets it is built from; each set is an object over the `Peer` with
its collaborators given at construction, and says which of its coroutines are
operations (`OperationSet.operations`). The service's sets are the repository
(`RepoOperations`, here), the views (`mapapi.service.view_ops`), the swarm
(`mapapi.service.transfer_ops`) and watches (`mapapi.service.watch_ops`); the
application adds its own (the maps') in `mapapi.app`, above both layers.

The CLI calls `Operations.call` directly when no peer daemon runs on the
repository, and through the control endpoint (`mapapi.service.control`) when one
does, so every command behaves the same either way. Arguments and results are
plain JSON values; ids are hex strings. Errors are `MapError`s, which travel as
(code, message) over the endpoint.
"""

from __future__ import annotations

import asyncio
import inspect
import os
from collections.abc import Awaitable, Callable, Iterable, Mapping
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, Protocol

from mapapi.core.change import Op
from mapapi.core.errors import CorruptPayload, PeerNotRunning, UsageError
from mapapi.core.history import CommitRecord, change_kind, number_commits
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId
from mapapi.core.limits import PEER_ADDRESS
from mapapi.core.table import check_new_table
from mapapi.store.file_check import locate_payload
from mapapi.swarm.voters import DEFAULT_REPLICATION

if TYPE_CHECKING:
    from mapapi.core.change import Change, Conflict
    from mapapi.core.history import Revision
    from mapapi.service.loop_lag import LoopLag
    from mapapi.service.peer import Peer
    from mapapi.store.base import IdKind

Json = Any
Operation = Callable[..., Awaitable[Json]]
"""One operation: a coroutine of JSON keyword arguments to a JSON result."""


class OperationSet(Protocol):
    """A group of operations over one peer."""

    def operations(self) -> Mapping[str, Operation]:
        """Name -> operation, for every operation of the set."""


class OperationsFactory(Protocol):
    """What builds the full `Operations` of a peer (`mapapi.app.operations`);
    the peer daemon takes one, so the application decides which sets it serves."""

    def __call__(
        self,
        peer: Peer,
        *,
        on_shutdown: Callable[[], None] | None = None,
        loop_lag: LoopLag | None = None,
    ) -> Operations:
        """The operations over `peer`; `on_shutdown` stops the daemon serving them,
        `loop_lag` watches its event loop (`peer status` reports it)."""


class Caller(Protocol):
    """`Operations`, or `mapapi.service.control.RemoteOperations` for a daemon's."""

    async def call(self, op: str, args: dict[str, Json]) -> Json:
        """Run one operation; its JSON result."""


PROGRESS_POLL_S = 0.2
"""Seconds between two questions of `call_polled` (a person's eye needs no more)."""


async def call_polled(
    ops: Caller,
    op: str,
    args: dict[str, Json],
    poll: tuple[str, dict[str, Json]],
    show: Callable[[Json], None],
) -> Json:
    """Run operation `op` while asking operation `poll` (name, arguments) how far
    it got, every `PROGRESS_POLL_S`; `show` gets each answer. For long operations
    of a daemon, whose progress another call must ask for."""
    call = asyncio.ensure_future(ops.call(op, args))
    try:
        while True:
            done, _ = await asyncio.wait({call}, timeout=PROGRESS_POLL_S)
            if done:
                return call.result()
            show(await ops.call(*poll))
    finally:
        if not call.done():
            call.cancel()


class Operations:
    """The CLI's operations over one peer: one table, name -> operation.

    Args:
        peer: the peer the operations run on.
        sets: the operation sets; no two may name the same operation.

    Raises:
        ValueError: two sets define one name.
    """

    def __init__(self, peer: Peer, sets: Iterable[OperationSet]) -> None:
        self.peer = peer
        table: dict[str, Operation] = {}
        for ops in sets:
            for name, operation in ops.operations().items():
                if name in table:
                    raise ValueError(f"operation {name!r} is defined twice")
                table[name] = operation
        self.table: Mapping[str, Operation] = MappingProxyType(table)
        # Each call's arguments are checked against its operation's signature, worked
        # out once here rather than by `inspect` on the event loop at every call.
        self._signatures = {name: inspect.signature(op) for name, op in table.items()}

    async def call(self, op: str, args: dict[str, Json]) -> Json:
        """Run the operation called `op` with keyword `args` (JSON in, JSON out).

        Raises:
            UsageError: no such operation, or arguments that do not fit it.
        """
        operation = self.table.get(op)
        if operation is None:
            raise UsageError(f"unknown operation {op!r}")
        try:
            self._signatures[op].bind(**args)
        except TypeError as exc:
            raise UsageError(f"bad arguments for {op!r}: {exc}") from exc
        try:
            return await operation(**args)
        except CorruptPayload as exc:  # name the file and the item (issue 18)
            located = locate_payload(exc, self.peer.store)
            if located is None:
                raise
            raise located from exc


# -- shapes shared by the sets -----------------------------------------------------------
def fields_json(peer: Peer, table: str, data: bytes | None) -> Json:
    """A payload of `table` as a dict of its fields (None for none)."""
    return None if data is None else peer.table(table).data_to_dict(data)


def revision_json(peer: Peer, revision: Revision | None) -> Json:
    """A revision's fields (None when there is none or it removed the item)."""
    if revision is None or revision.removed:
        return None
    return fields_json(peer, revision.table, revision.data)


def change_json(peer: Peer, change: Change | None) -> Json:
    """A staged change's fields (None for a removal)."""
    if change is None or change.op is Op.REMOVE:
        return None
    return fields_json(peer, change.table, change.data)


def conflict_json(peer: Peer, c: Conflict) -> Json:
    """One conflict: table, id, chunk and the base, ours and theirs fields."""
    return {
        "table": c.table,
        "id": c.item_id,
        "chunk": c.chunk_id,
        "base": revision_json(peer, c.base),
        "ours": change_json(peer, c.ours),
        "theirs": revision_json(peer, c.theirs),
    }


def commit_json(peer: Peer, record: CommitRecord, seq: int | None = None) -> Json:
    """A commit record; `author` is the writer's id, `author_name` its name
    (stored with the commit, else known here, else its short id), `view`
    the view it committed from; `seq` its number in this repository's log."""
    return {
        **({} if seq is None else {"seq": seq}),
        "commit": record.id,
        "time": record.time,
        "author": record.author,
        "author_name": record.author_name or _known_name(peer, record.author),
        "view": record.view,
        "message": record.message,
        "chunks": list(record.chunks),
    }


def _known_name(peer: Peer, peer_id: PeerId) -> str:
    """A peer's name as this peer knows it (itself, or the member list)."""
    if peer_id == peer.id:
        return peer.name
    swarm = peer.swarm
    member = swarm.members.get(peer_id) if swarm is not None else None
    return member.name if member is not None and member.name else peer_id.short


def resolve_id(peer: Peer, kind: IdKind, text: str) -> str:
    """A full id from a full id or a unique prefix of 4+ hex digits.

    Raises:
        UsageError: `text` is no id, or a prefix of none or several.
    """
    text = text.lower()
    if not 4 <= len(text) <= 32 or any(c not in "0123456789abcdef" for c in text):
        raise UsageError(f"bad {kind} id {text!r}: give 32 hex digits or a prefix of 4 or more")
    if len(text) == 32:
        return text
    found = peer.store.resolve_prefix(kind, text)
    if not found:
        raise UsageError(f"no {kind} id starts with {text!r}")
    if len(found) > 1:
        raise UsageError(f"{kind} id prefix {text!r} is ambiguous; give more digits")
    return found[0]


def check_address(address: str) -> str:
    """`address` if it looks like a peer address (tcp://HOST:PORT or ipc://PATH,
    with #curve=KEY for a secure peer).

    Raises:
        UsageError: it does not.
    """
    if not PEER_ADDRESS.fullmatch(address):
        raise UsageError(
            f"bad peer address {address!r}: give what `mapctl peer start` printed, "
            "e.g. tcp://192.168.1.10:7000"
        )
    return address


# -- the repository: ids, tables, chunks, history ----------------------------------------
class RepoOperations:
    """Ids, tables, chunks and history of the peer's repository."""

    def __init__(self, peer: Peer) -> None:
        self.peer = peer

    def operations(self) -> Mapping[str, Operation]:
        """See `OperationSet`."""
        return {
            "resolve_id": self.resolve_id,
            "table_create": self.table_create,
            "table_list": self.table_list,
            "chunk_create": self.chunk_create,
            "chunk_list": self.chunk_list,
            "log": self.log,
            "show": self.show,
        }

    async def resolve_id(self, kind: IdKind, text: str) -> str:
        """A full id from a full id or a unique prefix of 4+ hex digits."""
        return resolve_id(self.peer, kind, text)

    async def table_create(self, name: str, type_name: str, replication: int = 0) -> Json:
        """Create a table (refusing a name that cannot travel, or an unknown type),
        whose chunks' replication factor is `replication` (0: the default)."""
        check_new_table(name, type_name)
        descriptor = await self.peer.create_table(name, type_name, replication)
        factor = replication or DEFAULT_REPLICATION
        return {"name": descriptor.name, "type": descriptor.type_name, "replication": factor}

    async def table_list(self) -> Json:
        """Tables with chunk and item counts."""
        chunks = await self.peer.off_loop(self.peer.chunks)
        return {
            "tables": [
                {
                    "name": name,
                    "type": type_name,
                    "chunks": sum(1 for c in chunks if c.table == name),
                    "items": sum(c.items for c in chunks if c.table == name),
                }
                for name, type_name in self.peer.store.tables().items()
            ]
        }

    async def chunk_create(self, table: str, replication: int = 0) -> Json:
        """Create a chunk, with the replication factor `replication` (0: its table's)."""
        chunk = await self.peer.create_chunk(table, replication)
        return {"id": chunk, "table": table, "replication": self._factor(chunk)}

    def _factor(self, chunk: ChunkId) -> int:
        """The chunk's replication factor as its groups use it (its own, or the default)."""
        return self.peer.store.replication(chunk) or DEFAULT_REPLICATION

    async def chunk_list(self, table: str | None = None, peer: str | None = None) -> Json:
        """Chunks held here, or by the peer at address `peer` (asked over the network)."""
        if peer is not None:
            chunks = await self.peer.peer_chunks(check_address(peer), table)
            rows = [{"id": c.chunk, "table": c.table, "items": c.items} for c in chunks]
        else:
            rows = [
                {
                    "id": c.id,
                    "table": c.table,
                    "items": c.items,
                    "replication": self._factor(c.id),
                    "holders": self.peer.holders(c.id),
                    "roles": {str(p): r for p, r in self.peer.roles(c.id).items()},
                }
                for c in await self.peer.off_loop(self.peer.chunks, table)
            ]
        return {"chunks": rows}

    async def log(
        self, table: str | None = None, item: str | None = None, limit: int | None = None
    ) -> Json:
        """Commits newest first (of a table), or one item's revisions newest first."""
        peer = self.peer
        records = peer.log()
        seq = number_commits(records)  # over the whole log, whatever is shown
        if item is not None and table is not None:
            item_id = ItemId(resolve_id(peer, "item", item))
            peer.table(table)
            rows = []
            for revision in reversed(peer.history(item_id)):
                record = peer.commit_record(revision.commit_id)
                if record is None:  # a revision whose record is gone: what it says itself
                    record = CommitRecord(
                        revision.commit_id, revision.update_time, revision.author, "", ()
                    )
                row = commit_json(peer, record, seq.get(record.id))
                rows.append({**row, "data": revision_json(peer, revision)})
            return rows[:limit] if limit else rows
        if table is not None:
            peer.table(table)  # an unknown table is an error, not an empty log
            chunks = set(peer.store.chunk_ids(table))
            records = [r for r in records if chunks & set(r.chunks)]
        return [commit_json(peer, r, seq[r.id]) for r in records[:limit]]

    async def show(self, commit: str) -> Json:
        """One commit with the revisions it wrote."""
        peer = self.peer
        commit_id = CommitId(resolve_id(peer, "commit", commit))
        record = peer.commit_record(commit_id)
        if record is None:
            raise UsageError(f"no commit {commit_id}; `mapctl log` lists the commits")
        changes = []
        for revision in peer.commit_revisions(commit_id):
            previous = peer.read_local(revision.item_id, revision.update_time - 1)
            changes.append(
                {
                    "table": revision.table,
                    "id": revision.item_id,
                    "op": change_kind(revision, previous),
                    "data": revision_json(peer, revision),
                }
            )
        seq = number_commits(peer.log())[record.id]
        return {**commit_json(peer, record, seq), "changes": changes}


def chunk_arg(peer: Peer, chunk: str | None) -> ChunkId | None:
    """The full chunk id a (prefix) argument names, None for none."""
    return ChunkId(resolve_id(peer, "chunk", chunk)) if chunk else None


class DaemonOperations:
    """What only a peer daemon does: stop (`mapctl peer stop`).

    Args:
        on_shutdown: stops the daemon; None when no daemon serves these operations.
    """

    def __init__(self, on_shutdown: Callable[[], None] | None) -> None:
        self._on_shutdown = on_shutdown

    def operations(self) -> Mapping[str, Operation]:
        """See `OperationSet`."""
        return {"shutdown": self.shutdown}

    async def shutdown(self) -> Json:
        """Stop the peer daemon gracefully (`mapctl peer stop`)."""
        if self._on_shutdown is None:
            raise PeerNotRunning("no peer daemon runs on this repository")
        self._on_shutdown()
        return {"stopping": True, "pid": os.getpid()}
