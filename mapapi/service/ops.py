"""The operations `mapctl` performs, as JSON in and JSON out.

One `Operations` object wraps a `Peer` (and its views). The CLI calls it
directly when no peer daemon runs on the repository, and through the control
endpoint (`mapapi.service.control`) when one does, so every command behaves the same
either way. Arguments and results are plain JSON values; ids are hex strings.
Errors are `MapError`s, which travel as (code, message) over the endpoint.
"""

from __future__ import annotations

import inspect
import json
import os
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from mapapi.core.errors import CorruptPayload, ItemNotFound, PeerNotRunning, UsageError
from mapapi.core.history import CommitRecord, change_kind, number_commits
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId
from mapapi.core.limits import PEER_ADDRESS
from mapapi.core.table import check_new_table
from mapapi.core.transaction import Op
from mapapi.maps.operations import MapOperations
from mapapi.service.transfer_ops import TransferOperations
from mapapi.service.watch_ops import WatchOperations
from mapapi.service.workspace import Workspace
from mapapi.store.file_check import locate_payload

if TYPE_CHECKING:
    from mapapi.core.history import Revision
    from mapapi.core.transaction import Change, Conflict
    from mapapi.service.peer import Peer
    from mapapi.service.workspace import View
    from mapapi.store.base import IdKind

Json = Any


class Operations(WatchOperations, MapOperations, TransferOperations):
    """The CLI's operations over one peer (see the module docstring)."""

    def __init__(self, peer: Peer) -> None:
        self.peer = peer
        self._watches = {}
        self.views = Workspace(peer)
        self.on_shutdown: Callable[[], None] | None = None  # set by the peer daemon
        self._progress: dict[str, tuple[int, int]] = {}  # chunk -> (parts received, parts)

    async def call(self, op: str, args: dict[str, Json]) -> Json:
        """Run the operation called `op` with keyword `args` (JSON in, JSON out).

        Raises:
            UsageError: no such operation, or arguments that do not fit it.
        """
        method = getattr(self, op, None) if op in OPERATIONS else None
        if method is None:
            raise UsageError(f"unknown operation {op!r}")
        try:
            inspect.signature(method).bind(**args)
        except TypeError as exc:
            raise UsageError(f"bad arguments for {op!r}: {exc}") from exc
        try:
            return await method(**args)
        except CorruptPayload as exc:  # name the file and the item (issue 18)
            located = locate_payload(exc, self.peer.store)
            if located is None:
                raise
            raise located from exc

    # -- shapes ------------------------------------------------------------------
    def _fields(self, table: str, data: bytes | None) -> Json:
        return None if data is None else self.peer.table(table).data_to_dict(data)

    def _revision(self, revision: Revision | None) -> Json:
        if revision is None or revision.removed:
            return None
        return self._fields(revision.table, revision.data)

    def _change(self, change: Change | None) -> Json:
        if change is None or change.op is Op.REMOVE:
            return None
        return self._fields(change.table, change.data)

    def conflict(self, c: Conflict) -> Json:
        """One conflict: table, id, chunk and the base, ours and theirs fields."""
        return {
            "table": c.table,
            "id": c.item_id,
            "chunk": c.chunk_id,
            "base": self._revision(c.base),
            "ours": self._change(c.ours),
            "theirs": self._revision(c.theirs),
        }

    def commit_json(self, record: CommitRecord, seq: int | None = None) -> Json:
        """A commit record; `author` is the writer's id, `author_name` its name
        (stored with the commit, else known here, else its short id), `view`
        the view it committed from; `seq` its number in this repository's log."""
        return {
            **({} if seq is None else {"seq": seq}),
            "commit": record.id,
            "time": record.time,
            "author": record.author,
            "author_name": record.author_name or self._known_name(record.author),
            "view": record.view,
            "message": record.message,
            "chunks": list(record.chunks),
        }

    def _known_name(self, peer_id: PeerId) -> str:
        """A peer's name as this peer knows it (itself, or the member list)."""
        if peer_id == self.peer.id:
            return self.peer.name
        swarm = self.peer.swarm
        member = swarm.members.get(peer_id) if swarm is not None else None
        return member.name if member is not None and member.name else peer_id.short

    @staticmethod
    def view_json(view: View) -> Json:
        """A view's name, begin time and counts."""
        return {
            "name": view.name,
            "begin_time": view.begin_time,
            "isolation": view.isolation,
            "staged": len(view.changes),
            "conflicts": len(view.conflicts),
        }

    # -- ids -------------------------------------------------------------------------
    async def resolve_id(self, kind: IdKind, text: str) -> str:
        """A full id from a full id or a unique prefix of 4+ hex digits."""
        text = text.lower()
        if not 4 <= len(text) <= 32 or any(c not in "0123456789abcdef" for c in text):
            raise UsageError(f"bad {kind} id {text!r}: give 32 hex digits or a prefix of 4 or more")
        if len(text) == 32:
            return text
        found = self.peer.store.resolve_prefix(kind, text)
        if not found:
            raise UsageError(f"no {kind} id starts with {text!r}")
        if len(found) > 1:
            raise UsageError(f"{kind} id prefix {text!r} is ambiguous; give more digits")
        return found[0]

    # -- tables and chunks -------------------------------------------------------------
    async def table_create(self, name: str, type_name: str) -> Json:
        """Create a table (refusing a name that cannot travel, or an unknown type)."""
        check_new_table(name, type_name)
        descriptor = await self.peer.create_table(name, type_name)
        return {"name": descriptor.name, "type": descriptor.type_name}

    async def table_list(self) -> Json:
        """Tables with chunk and item counts."""
        chunks = self.peer.chunks()
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

    async def chunk_create(self, table: str) -> Json:
        """Create a chunk."""
        return {"id": await self.peer.create_chunk(table), "table": table}

    async def chunk_list(self, table: str | None = None, peer: str | None = None) -> Json:
        """Chunks held here, or by the peer at address `peer` (asked over the network)."""
        if peer is not None:
            chunks = await self.peer.peer_chunks(check_address(peer), table)
            rows = [{"id": c.chunk, "table": c.table, "items": c.items} for c in chunks]
        else:
            rows = [
                {"id": c.id, "table": c.table, "items": c.items, "holders": self.peer.holders(c.id)}
                for c in self.peer.chunks(table)
            ]
        return {"chunks": rows}

    # -- views ---------------------------------------------------------------------------
    async def view_open(self, view: str, at: int | None = None, serializable: bool = False) -> Json:
        """Begin a view."""
        opened = self.views.open(view, at, "serializable" if serializable else "snapshot")
        return self.view_json(opened)

    async def view_abort(self, view: str) -> Json:
        """Drop a view."""
        self.views.abort(view)
        return {"view": view}

    async def view_list(self) -> Json:
        """Every view."""
        return {"views": [self.view_json(v) for v in self.views.views()]}

    async def status(self, view: str) -> Json:
        """A view's begin time, staged changes and conflicts."""
        current = self.views.get(view)
        return {
            "view": view,
            "open": current is not None,
            "begin_time": current.begin_time if current else None,
            "now": self.peer.now(),
            "staged": [
                {"op": c.op.name.lower(), "table": c.table, "id": c.item_id, "chunk": c.chunk_id}
                for c in (current.changes if current else [])
            ],
            "conflicts": [c.item_id for c in (current.conflicts if current else [])],
        }

    async def set(
        self, view: str, table: str, data: str, item: str | None = None, chunk: str | None = None
    ) -> Json:
        """Stage an insert (no item) or an update."""
        item_id = ItemId(await self.resolve_id("item", item)) if item else None
        chunk_id = ChunkId(await self.resolve_id("chunk", chunk)) if chunk else None
        staged = self.views.stage_set(view, table, data, item_id, chunk_id)
        return {"id": staged, "op": "update" if item_id else "insert"}

    async def rm(self, view: str, table: str, item: str) -> Json:
        """Stage a removal."""
        item_id = ItemId(await self.resolve_id("item", item))
        self.views.stage_remove(view, table, item_id)
        return {"id": item_id, "op": "remove"}

    async def get(self, view: str, table: str, item: str, at: int | None = None) -> Json:
        """One item's fields as the view (or the map at `at`) sees it."""
        item_id = ItemId(await self.resolve_id("item", item))
        tx = self.views.reader(view, at)
        message = await tx.get(table, item_id)
        if at is None:
            self.views.remember_reads(view, tx)
        if message is None:
            raise ItemNotFound(
                f"no item {item_id} in table {table!r} at time {tx.begin_time}; "
                f"`mapctl ls {table}` lists the items"
            )
        return {
            "id": item_id,
            "time": tx.begin_time,
            "data": self.peer.table(table).to_dict(message),
        }

    async def ls(
        self, view: str, table: str, chunk: str | None = None, at: int | None = None
    ) -> Json:
        """The items of a table (or chunk) as the view sees them."""
        chunk_id = ChunkId(await self.resolve_id("chunk", chunk)) if chunk else None
        tx = self.views.reader(view, at)
        descriptor = self.peer.table(table)
        found = await tx.items(table, chunk_id)
        if at is None:
            self.views.remember_reads(view, tx)
        return {
            "time": tx.begin_time,
            "items": [{"id": i, "data": descriptor.to_dict(m)} for i, m in found.items()],
        }

    async def commit(self, view: str, message: str = "") -> Json:
        """Commit a view; raises ConflictError (the conflicts stay in the view)."""
        record = await self.views.commit(view, message)
        return self.commit_json(record) if record else {"commit": None}

    async def diff(self, view: str) -> Json:
        """Staged changes (with their base) and conflicts of a view."""
        current = self.views.get(view)
        changes, conflicts = [], []
        if current is not None:
            for ch in current.changes:
                base = self.peer.read_local(ch.item_id, current.begin_time)
                changes.append(
                    {
                        "table": ch.table,
                        "id": ch.item_id,
                        "chunk": ch.chunk_id,
                        "op": ch.op.name.lower(),
                        "base": self._revision(base),
                        "ours": self._change(ch),
                    }
                )
            conflicts = [self.conflict(c) for c in current.conflicts]
        return {"view": view, "changes": changes, "conflicts": conflicts}

    async def match_conflict(self, view: str, text: str) -> Json:
        """The full item id of the view's one conflict whose id starts with `text`."""
        current = self.views.get(view)
        return _match(current.conflicts if current else [], text)

    async def resolve(
        self,
        view: str,
        side: str,
        items: list[str] | None = None,
        edited: dict[str, Json] | None = None,
        force: bool = False,
    ) -> Json:
        """Settle conflicts with `side` ('ours' or 'theirs'), or edited fields per item;
        `force` discards edits staged after the conflict (see `Workspace.resolve`)."""
        if side not in ("ours", "theirs"):
            raise UsageError(f"side must be 'ours' or 'theirs', not {side!r}")
        current = self.views.get(view)
        conflicts = current.conflicts if current else []
        if not conflicts:
            raise UsageError(f"view {view!r} has no conflicts to resolve")
        wanted = [_match(conflicts, text) for text in items or []]
        payloads = {}
        for text, fields in (edited or {}).items():
            conflict = next(c for c in conflicts if c.item_id == _match(conflicts, text))
            descriptor = self.peer.table(conflict.table)
            payloads[conflict.item_id] = descriptor.encode(descriptor.from_json(json.dumps(fields)))
        resolved = self.views.resolve(
            view,
            side,  # type: ignore[arg-type]
            wanted,
            payloads,
            force=force,
        )
        return {"resolved": resolved, "remaining": len(conflicts) - len(resolved)}

    # -- history ---------------------------------------------------------------------
    async def log(
        self, table: str | None = None, item: str | None = None, limit: int | None = None
    ) -> Json:
        """Commits newest first (of a table), or one item's revisions newest first."""
        peer = self.peer
        records = peer.log()
        seq = number_commits(records)  # over the whole log, whatever is shown
        if item is not None and table is not None:
            item_id = ItemId(await self.resolve_id("item", item))
            peer.table(table)
            rows = []
            for revision in reversed(peer.history(item_id)):
                record = peer.commit_record(revision.commit_id)
                if record is None:  # a revision whose record is gone: what it says itself
                    record = CommitRecord(
                        revision.commit_id, revision.update_time, revision.author, "", ()
                    )
                row = self.commit_json(record, seq.get(record.id))
                rows.append({**row, "data": self._revision(revision)})
            return rows[:limit] if limit else rows
        if table is not None:
            chunks = {c.id for c in peer.chunks(table)}
            records = [r for r in records if chunks & set(r.chunks)]
        return [self.commit_json(r, seq[r.id]) for r in records[:limit]]

    async def show(self, commit: str) -> Json:
        """One commit with the revisions it wrote."""
        commit_id = CommitId(await self.resolve_id("commit", commit))
        record = self.peer.commit_record(commit_id)
        if record is None:
            raise UsageError(f"no commit {commit_id}; `mapctl log` lists the commits")
        changes = []
        for revision in self.peer.commit_revisions(commit_id):
            previous = self.peer.read_local(revision.item_id, revision.update_time - 1)
            changes.append(
                {
                    "table": revision.table,
                    "id": revision.item_id,
                    "op": change_kind(revision, previous),
                    "data": self._revision(revision),
                }
            )
        seq = number_commits(self.peer.log())[record.id]
        return {**self.commit_json(record, seq), "changes": changes}

    # -- the swarm (only while the peer daemon runs) ------------------------------------
    def _on_swarm(self) -> Peer:
        if self.peer.swarm is None:
            raise PeerNotRunning(
                "no peer runs on this repository; start it with `mapctl peer start --detach` "
                "(or `mapctl peer start` in another terminal)"
            )
        return self.peer

    async def peer_status(self) -> Json:
        """This peer: id, name, the address others join through, every member."""
        peer = self._on_swarm()
        assert peer.swarm is not None
        members = [
            {"id": m.id, "address": m.address, "name": m.name} for m in peer.swarm.members.all()
        ]
        return {
            "id": peer.id,
            "name": peer.name,
            "address": peer.address,
            "join": peer.address,
            "pid": os.getpid(),
            "members": members,
            "chunks": len(peer.chunks()),
        }

    async def peers(self) -> Json:
        """The other members: id, address, name, seconds since last heard of
        (None: never heard from directly) and the chunks both peers hold."""
        peer = self._on_swarm()
        now = time.monotonic()
        held = [c.id for c in peer.chunks()]
        rows = []
        for state in peer.members():
            member = state.member
            seen = state.last_seen
            rows.append(
                {
                    "id": member.id,
                    "address": member.address,
                    "name": member.name,
                    "last_seen": None if seen is None else round(now - seen, 3),
                    "shared_chunks": [c for c in held if member.id in peer.store.holders(c)],
                }
            )
        return {"peers": rows}

    async def join(self, address: str) -> Json:
        """Join the swarm through the member listening at `address`."""
        peer = self._on_swarm()
        members = await peer.join(check_address(address))
        return {
            "joined": address,
            "members": [{"id": m.id, "address": m.address, "name": m.name} for m in members],
        }

    async def participate(self, chunk: str) -> Json:
        """Replicate a chunk here, with its history, from any holder."""
        peer = self._on_swarm()
        try:
            chunk_id = ChunkId(await self.resolve_id("chunk", chunk))
        except UsageError as exc:
            raise UsageError(
                f"{exc}; a chunk this peer does not hold needs its full 32-digit id "
                "(`mapctl chunk list` on a peer that holds it)"
            ) from None

        def report(received: int, parts: int) -> None:
            self._progress[chunk] = (received, parts)

        self._progress[chunk] = (0, 0)
        try:
            table = await peer.participate(chunk_id, report, again=True)
        finally:
            self._progress.pop(chunk, None)
        items = next((c.items for c in peer.chunks() if c.id == chunk_id), 0)
        return {
            "chunk": chunk_id,
            "table": table,
            "items": items,
            "holders": peer.holders(chunk_id),
        }

    async def participate_progress(self, chunk: str) -> Json:
        """How far a running `participate(chunk)` got: parts received of all parts
        (0 of 0 before the first part, or when none runs)."""
        received, parts = self._progress.get(chunk, (0, 0))
        return {"chunk": chunk, "received": received, "parts": parts}

    async def chunk_leave(self, chunk: str, force: bool = False) -> Json:
        """Stop replicating a chunk (the last holder needs `force`)."""
        peer = self._on_swarm()
        chunk_id = ChunkId(await self.resolve_id("chunk", chunk))
        peer.chunk_table(chunk_id)  # NotParticipatingError if it is not held here
        await peer.leave_chunk(chunk_id, force=force)
        return {"chunk": chunk_id, "left": True}

    async def swarm_chunks(self) -> Json:
        """Every chunk a member of the swarm (this peer included) holds."""
        from mapapi.service.control import ask_chunk_lists

        peer = self._on_swarm()
        found: dict[str, Json] = {
            c.id: {"id": c.id, "table": c.table, "holders": [peer.id]} for c in peer.chunks()
        }
        for member, chunks in (await ask_chunk_lists(peer)).items():
            for c in chunks:
                entry = found.setdefault(c.chunk, {"id": c.chunk, "table": c.table, "holders": []})
                entry["holders"].append(member)
        return {"chunks": [found[k] for k in sorted(found)]}

    async def shutdown(self) -> Json:
        """Stop the peer daemon gracefully (`mapctl peer stop`)."""
        if self.on_shutdown is None:
            raise PeerNotRunning("no peer daemon runs on this repository")
        self.on_shutdown()
        return {"stopping": True, "pid": os.getpid()}


OPERATIONS = frozenset(
    name
    for cls in Operations.__mro__
    for name, value in vars(cls).items()
    if not name.startswith("_") and name != "call" and inspect.iscoroutinefunction(value)
)


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


def _match(conflicts: list[Conflict], text: str) -> ItemId:
    found = [c.item_id for c in conflicts if c.item_id.startswith(text.lower())]
    if len(found) != 1:
        raise UsageError(f"{text!r} names {len(found)} of the view's conflicts; give a unique id")
    return found[0]
