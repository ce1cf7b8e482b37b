"""The operations on named views (`mapctl set|rm|get|ls|status|diff|commit|resolve`
and `view ...`), JSON in and out; a set of `mapapi.service.ops.Operations`."""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from mapapi.core.errors import ItemNotFound, UsageError
from mapapi.core.ids import ItemId
from mapapi.core.table import TableDescriptor
from mapapi.service.ops import (
    Operation,
    change_json,
    chunk_arg,
    commit_json,
    conflict_json,
    resolve_id,
    revision_json,
)
from mapapi.service.stale import staleness
from mapapi.store.offload import off_loop

if TYPE_CHECKING:
    from mapapi.core.change import Conflict
    from mapapi.core.transaction import Isolation
    from mapapi.service.peer import Peer
    from mapapi.service.workspace import View, Workspace

Json = Any


def _rows(descriptor: TableDescriptor, found: dict[ItemId, bytes]) -> list[Json]:
    """Each item decoded, as `ls` answers it (any thread)."""
    return [{"id": i, "data": descriptor.to_dict(descriptor.decode(d))} for i, d in found.items()]


def view_json(view: View) -> Json:
    """A view's name, begin time and counts."""
    return {
        "name": view.name,
        "begin_time": view.begin_time,
        "isolation": view.isolation,
        "stale": view.stale,
        "staged": len(view.changes),
        "conflicts": len(view.conflicts),
    }


class ViewOperations:
    """Staging, reading and committing through the named views of `views`.

    Args:
        peer: the peer the views read and commit through.
        views: its workspace (the views persist in the peer's store).
    """

    def __init__(self, peer: Peer, views: Workspace) -> None:
        self.peer = peer
        self.views = views

    def operations(self) -> Mapping[str, Operation]:
        """See `mapapi.service.ops.OperationSet`."""
        return {
            "view_open": self.view_open,
            "view_abort": self.view_abort,
            "view_list": self.view_list,
            "status": self.status,
            "set": self.set,
            "rm": self.rm,
            "get": self.get,
            "ls": self.ls,
            "commit": self.commit,
            "diff": self.diff,
            "match_conflict": self.match_conflict,
            "resolve": self.resolve,
        }

    async def view_open(
        self, view: str, at: int | None = None, serializable: bool = False, stale: bool = False
    ) -> Json:
        """Begin a view (`stale`: on the replicas as they are, and how old they may be)."""
        isolation: Isolation = "serializable" if serializable else "snapshot"
        opened = view_json(self.views.open(view, at, isolation, stale))
        if stale:
            opened["replicas"] = staleness(self.peer).as_dict()
        return opened

    async def view_abort(self, view: str) -> Json:
        """Drop a view."""
        self.views.abort(view)
        return {"view": view}

    async def view_list(self) -> Json:
        """Every view."""
        return {"views": [view_json(v) for v in self.views.views()]}

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
        item_id = ItemId(resolve_id(self.peer, "item", item)) if item else None
        if item_id is not None:
            await self.views.pin(view, item_id)
        staged = self.views.stage_set(view, table, data, item_id, chunk_arg(self.peer, chunk))
        return {"id": staged, "op": "update" if item_id else "insert"}

    async def rm(self, view: str, table: str, item: str) -> Json:
        """Stage a removal."""
        item_id = ItemId(resolve_id(self.peer, "item", item))
        await self.views.pin(view, item_id)
        self.views.stage_remove(view, table, item_id)
        return {"id": item_id, "op": "remove"}

    async def get(self, view: str, table: str, item: str, at: int | None = None) -> Json:
        """One item's fields as the view (or the map at `at`) sees it."""
        item_id = ItemId(resolve_id(self.peer, "item", item))
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
        chunk_id = chunk_arg(self.peer, chunk)
        tx = self.views.reader(view, at)
        descriptor = self.peer.table(table)
        found = await tx.payloads(table, chunk_id)
        if at is None:
            self.views.remember_reads(view, tx)
        # 50,000 rows are seconds of decoding: a worker's, not the loop's (issue 14 §1)
        rows = await off_loop(self.peer.store, _rows, descriptor, found)
        return {"time": tx.begin_time, "items": rows}

    async def commit(self, view: str, message: str = "") -> Json:
        """Commit a view; raises ConflictError (the conflicts stay in the view)."""
        record = await self.views.commit(view, message)
        return commit_json(self.peer, record) if record else {"commit": None}

    async def diff(self, view: str) -> Json:
        """Staged changes (with their base) and conflicts of a view."""
        peer = self.peer
        current = self.views.get(view)
        changes, conflicts = [], []
        if current is not None:
            for ch in current.changes:
                base = peer.read_local(ch.item_id, current.begin_time)
                changes.append(
                    {
                        "table": ch.table,
                        "id": ch.item_id,
                        "chunk": ch.chunk_id,
                        "op": ch.op.name.lower(),
                        "base": revision_json(peer, base),
                        "ours": change_json(peer, ch),
                    }
                )
            conflicts = [conflict_json(peer, c) for c in current.conflicts]
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


def _match(conflicts: list[Conflict], text: str) -> ItemId:
    found = [c.item_id for c in conflicts if c.item_id.startswith(text.lower())]
    if len(found) != 1:
        raise UsageError(f"{text!r} names {len(found)} of the view's conflicts; give a unique id")
    return found[0]
