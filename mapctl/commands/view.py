"""Views and staging: `view ...`, `status`, `set`, `get`, `ls`, `rm`, `commit`, `diff`,
`resolve`."""

from __future__ import annotations

import json
import sys
from typing import TYPE_CHECKING, Any

import click

from mapctl.session import Session, json_option, pass_session

if TYPE_CHECKING:
    from mapapi import Conflict, ItemId


@click.group("view")
def view() -> None:
    """Open, list and abort named views (`--view NAME`, default main)."""


@view.command("open")
@click.option("--at", "at", type=int, help="Begin at this past logical time instead of now.")
@click.option("--serializable", is_flag=True, help="Also validate what the view reads.")
@json_option
@pass_session
def view_open(session: Session, at: int | None, serializable: bool, as_json: bool) -> None:
    """Begin a view: later reads see the map as of its begin time."""
    from mapctl import render, shape

    opened = session.workspace.open(
        session.view, at, "serializable" if serializable else "snapshot"
    )
    if as_json:
        render.emit_json(shape.view_summary(opened))
    else:
        render.line(f"view {opened.name} open at time {opened.begin_time}")


@view.command("abort")
@pass_session
def view_abort(session: Session) -> None:
    """Drop the view's staged changes and conflicts."""
    from mapctl import render

    session.workspace.abort(session.view)
    render.line(f"view {session.view} aborted")


@view.command("list")
@json_option
@pass_session
def view_list(session: Session, as_json: bool) -> None:
    """List the open views."""
    from mapctl import render, shape

    rows = [shape.view_summary(v) for v in session.workspace.views()]
    if as_json:
        render.emit_json({"views": rows})
    else:
        render.table(
            "views",
            ["name", "begin time", "isolation", "staged", "conflicts"],
            [r.values() for r in rows],
        )


@click.command("status")
@json_option
@pass_session
def status(session: Session, as_json: bool) -> None:
    """Show the view, its begin time, staged changes and conflicts."""
    from mapctl import render

    current = session.workspace.get(session.view)
    now = session.peer.now()
    info: dict[str, Any] = {
        "view": session.view,
        "open": current is not None,
        "begin_time": current.begin_time if current else None,
        "now": now,
        "staged": [
            {"op": c.op.name.lower(), "table": c.table, "id": c.item_id, "chunk": c.chunk_id}
            for c in (current.changes if current else [])
        ],
        "conflicts": [c.item_id for c in (current.conflicts if current else [])],
    }
    if as_json:
        render.emit_json(info)
        return
    if current is None:
        render.line(f"view {session.view}: not open (now = {now}); `set` opens it")
        return
    render.line(f"view {session.view} at time {current.begin_time} (now = {now})")
    render.table(
        "staged changes",
        ["op", "table", "id"],
        [(s["op"], s["table"], s["id"]) for s in info["staged"]],
    )
    if current.conflicts:
        render.line(f"{len(current.conflicts)} unresolved conflict(s): run `mapctl diff`", "yellow")


def _read_data(text: str) -> str:
    if text == "-":
        return sys.stdin.read()
    if text.startswith("@"):
        try:
            with open(text[1:], encoding="utf-8") as handle:
                return handle.read()
        except OSError as exc:
            raise click.BadParameter(f"cannot read {text[1:]}: {exc.strerror}") from exc
    return text


@click.command("set")
@click.argument("table_name", metavar="TABLE")
@click.argument("args", nargs=-1, required=True, metavar="[ID] DATA")
@click.option("--chunk", "chunk", help="The chunk of a new item (inserts only).")
@json_option
@pass_session
def set_item(
    session: Session, table_name: str, args: tuple[str, ...], chunk: str | None, as_json: bool
) -> None:
    """Stage an insert (no ID) or an update of ID. DATA is JSON, @FILE or - for stdin."""
    from mapapi import ChunkId, ItemId
    from mapctl import render

    if len(args) > 2:
        raise click.UsageError("expected TABLE [ID] DATA; quote DATA as one argument")
    item = ItemId(session.resolve_id("item", args[0])) if len(args) == 2 else None
    chunk_id = ChunkId(session.resolve_id("chunk", chunk)) if chunk else None
    item_id = session.workspace.stage_set(
        session.view, table_name, _read_data(args[-1]), item, chunk_id
    )
    if as_json:
        render.emit_json({"id": item_id, "op": "update" if item else "insert"})
    else:
        render.line(item_id)


@click.command("get")
@click.argument("table_name", metavar="TABLE")
@click.argument("item", metavar="ID")
@click.option("--at", "at", type=int, help="Read at this logical time (ignores the view).")
@json_option
@pass_session
def get_item(session: Session, table_name: str, item: str, at: int | None, as_json: bool) -> None:
    """Print one item's fields (the view's snapshot plus its staged changes)."""
    from mapapi import ItemId, ItemNotFound
    from mapctl import render

    item_id = ItemId(session.resolve_id("item", item))
    tx = session.workspace.reader(session.view, at)
    message = session.run(tx.get(table_name, item_id))
    if message is None:
        raise ItemNotFound(
            f"no item {item_id} in table {table_name!r} at time {tx.begin_time}; "
            f"`mapctl ls {table_name}` lists the items"
        )
    fields = session.peer.table(table_name).to_dict(message)
    if as_json:
        render.emit_json(fields)
    else:
        render.pretty_json(fields)


@click.command("ls")
@click.argument("table_name", metavar="TABLE")
@click.option("--chunk", "chunk", help="Only this chunk.")
@click.option("--at", "at", type=int, help="List at this logical time (ignores the view).")
@json_option
@pass_session
def ls(session: Session, table_name: str, chunk: str | None, at: int | None, as_json: bool) -> None:
    """List the items of TABLE as the view sees them."""
    from mapapi import ChunkId
    from mapctl import render

    chunk_id = ChunkId(session.resolve_id("chunk", chunk)) if chunk else None
    tx = session.workspace.reader(session.view, at)
    descriptor = session.peer.table(table_name)
    found = session.run(tx.items(table_name, chunk_id))
    rows = [{"id": i, "data": descriptor.to_dict(m)} for i, m in found.items()]
    if as_json:
        render.emit_json({"items": rows})
    else:
        render.table(
            f"items of {table_name} at time {tx.begin_time}",
            ["id", "data"],
            [(r["id"], json.dumps(r["data"])) for r in rows],
        )


@click.command("rm")
@click.argument("table_name", metavar="TABLE")
@click.argument("item", metavar="ID")
@pass_session
def rm(session: Session, table_name: str, item: str) -> None:
    """Stage the removal of an item."""
    from mapapi import ItemId
    from mapctl import render

    item_id = ItemId(session.resolve_id("item", item))
    session.workspace.stage_remove(session.view, table_name, item_id)
    render.line(f"staged removal of {item_id}")


@click.command("commit")
@click.option("-m", "--message", default="", help="The commit message.")
@json_option
@pass_session
def commit(session: Session, message: str, as_json: bool) -> None:
    """Commit the view's staged changes. Exits 3 on conflict; the conflicts stay in the view."""
    from mapapi import ConflictError
    from mapctl import render, shape

    try:
        record = session.run(session.workspace.commit(session.view, message))
    except ConflictError as err:
        if as_json:
            render.emit_json(
                {"conflicts": [shape.conflict(session.peer, c) for c in err.conflicts]}
            )
        raise
    info = shape.commit(record) if record else {"commit": None}
    if as_json:
        render.emit_json(info)
    elif record is not None:
        render.line(f"[{record.id[:8]}] time {record.time}: {message or '(no message)'}", "green")
    else:
        render.line(f"nothing to write; view {session.view} closed")


@click.command("diff")
@json_option
@pass_session
def diff(session: Session, as_json: bool) -> None:
    """Show the staged changes, and the conflicts after a failed commit."""
    from mapctl import render, shape

    current = session.workspace.get(session.view)
    changes = shape.staged(session.peer, current) if current else []
    conflicts = [shape.conflict(session.peer, c) for c in (current.conflicts if current else [])]
    if as_json:
        render.emit_json({"view": session.view, "changes": changes, "conflicts": conflicts})
        return
    if not changes and not conflicts:
        render.line(f"view {session.view}: nothing staged")
    for ch in changes:
        sides = {"base": ch["base"], "ours": ch["ours"]}
        render.side_by_side(f"{ch['op']} {ch['table']} {ch['id']}", sides)
    for c in conflicts:
        sides = {"base": c["base"], "ours": c["ours"], "theirs": c["theirs"]}
        render.side_by_side(f"conflict {c['table']} {c['id']}", sides, conflict=True)


def _pick(session: Session, conflict: Conflict) -> tuple[str, bytes | None]:
    """Ask how to settle one conflict on a TTY: ours, theirs, edit or skip."""
    from mapctl import render, shape

    c = shape.conflict(session.peer, conflict)
    render.side_by_side(
        f"conflict {c['table']} {c['id']}",
        {"base": c["base"], "ours": c["ours"], "theirs": c["theirs"]},
        conflict=True,
    )
    answer = click.prompt(
        "keep [o]urs, [t]heirs, [e]dit, [s]kip",
        type=click.Choice(["o", "t", "e", "s"]),
        default="s",
    )
    if answer != "e":
        return {"o": "ours", "t": "theirs", "s": "skip"}[answer], None
    start = c["ours"] if c["ours"] is not None else c["theirs"]
    text = click.edit(json.dumps(start, indent=2) + "\n", extension=".json")
    if text is None:
        return "skip", None
    descriptor = session.peer.table(conflict.table)
    return "edit", descriptor.encode(descriptor.from_json(text))


@click.command("resolve")
@click.argument("items", nargs=-1, metavar="[ID ...]")
@click.option("--ours", "side", flag_value="ours", help="Keep our side.")
@click.option("--theirs", "side", flag_value="theirs", help="Keep their side.")
@json_option
@pass_session
def resolve(session: Session, items: tuple[str, ...], side: str | None, as_json: bool) -> None:
    """Settle conflicts (all, or the IDs given). On a TTY with neither flag, ask per conflict."""
    from mapapi import UsageError, ViewClosedError
    from mapctl import render

    current = session.workspace.get(session.view)
    if current is None or not current.conflicts:
        raise ViewClosedError(f"view {session.view!r} has no conflicts to resolve")
    wanted = [_match_conflict(current.conflicts, text) for text in items]
    resolved: list[ItemId] = []
    if side in ("ours", "theirs"):
        resolved = session.workspace.resolve(session.view, side, wanted)  # type: ignore[arg-type]
    elif sys.stdin.isatty():
        for conflict in current.conflicts:
            if wanted and conflict.item_id not in wanted:
                continue
            choice, data = _pick(session, conflict)
            if choice == "skip":
                continue
            edited = {conflict.item_id: data} if data is not None else None
            pick = "theirs" if choice == "theirs" else "ours"
            resolved += session.workspace.resolve(session.view, pick, [conflict.item_id], edited)
    else:
        raise UsageError("say --ours or --theirs (no terminal to ask on)")
    left = len(current.conflicts) - len(resolved)
    if as_json:
        render.emit_json({"resolved": resolved, "remaining": left})
    else:
        render.line(f"resolved {len(resolved)} conflict(s); {left} left", "green")


def _match_conflict(conflicts: list[Conflict], text: str) -> ItemId:
    from mapapi import UsageError

    found = [c.item_id for c in conflicts if c.item_id.startswith(text.lower())]
    if len(found) != 1:
        raise UsageError(f"{text!r} names {len(found)} of the view's conflicts; give a unique id")
    return found[0]


def register(cli: click.Group) -> None:
    """Add this module's commands to `cli`."""
    for command in (view, status, set_item, get_item, ls, rm, commit, diff, resolve):
        cli.add_command(command)
