"""Turn library values into the JSON shapes `mapctl` prints (the CLI contract)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from mapapi import Change, CommitRecord, Conflict, Peer, Revision
    from mapapi.workspace import View


def payload(peer: Peer, table: str, data: bytes | None) -> Any:
    """An item's fields as a JSON value; None when absent."""
    if data is None:
        return None
    return peer.table(table).data_to_dict(data)


def revision_fields(peer: Peer, revision: Revision | None) -> Any:
    """A revision's fields; None when absent or removed."""
    if revision is None or revision.removed:
        return None
    return payload(peer, revision.table, revision.data)


def change_fields(peer: Peer, change: Change | None) -> Any:
    """A staged change's new fields; None for a removal or no change."""
    from mapapi import Op

    if change is None or change.op is Op.REMOVE:
        return None
    return payload(peer, change.table, change.data)


def commit(record: CommitRecord) -> dict[str, Any]:
    """A commit record."""
    return {
        "commit": record.id,
        "time": record.time,
        "author": record.author,
        "message": record.message,
        "chunks": list(record.chunks),
    }


def conflict(peer: Peer, c: Conflict) -> dict[str, Any]:
    """One conflict: table, id, and the base, ours and theirs fields."""
    return {
        "table": c.table,
        "id": c.item_id,
        "chunk": c.chunk_id,
        "base": revision_fields(peer, c.base),
        "ours": change_fields(peer, c.ours),
        "theirs": revision_fields(peer, c.theirs),
    }


def staged(peer: Peer, view: View) -> list[dict[str, Any]]:
    """A view's staged changes with the base each one replaces."""
    out = []
    for ch in view.changes:
        base = peer.read_local(ch.item_id, view.begin_time)
        out.append(
            {
                "table": ch.table,
                "id": ch.item_id,
                "chunk": ch.chunk_id,
                "op": ch.op.name.lower(),
                "base": revision_fields(peer, base),
                "ours": change_fields(peer, ch),
            }
        )
    return out


def view_summary(view: View) -> dict[str, Any]:
    """A view's name, begin time and counts."""
    return {
        "name": view.name,
        "begin_time": view.begin_time,
        "isolation": view.isolation,
        "staged": len(view.changes),
        "conflicts": len(view.conflicts),
    }
