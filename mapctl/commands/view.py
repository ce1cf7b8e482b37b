"""Views and staging: `view ...`, `status`, `set`, `get`, `ls`, `rm`.

Plus `commit`, `diff` and `resolve`.
"""

from __future__ import annotations

import json
import sys
from typing import Any

import click

from mapctl.session import Session, json_option, pass_session


@click.group("view")
def view() -> None:
    """Open, list and abort named views (`--view NAME`, default main)."""


@view.command("open")
@click.option("--at", "at", type=int, help="Begin at this past logical time instead of now.")
@click.option("--serializable", is_flag=True, help="Also validate what the view reads.")
@click.option(
    "--stale",
    is_flag=True,
    help="Read this peer's replicas as they are, asking no leader (works offline).",
)
@json_option
@pass_session
def view_open(
    session: Session, at: int | None, serializable: bool, stale: bool, as_json: bool
) -> None:
    """Begin a view: later reads see the map as of its begin time."""
    from mapctl import render

    opened = session.call(
        "view_open", view=session.view, at=at, serializable=serializable, stale=stale
    )
    if as_json:
        render.emit_json(opened)
        return
    render.line(f"view {opened['name']} open at time {opened['begin_time']}")
    if stale:
        render.line(render.staleness(opened["replicas"]))


@view.command("abort")
@pass_session
def view_abort(session: Session) -> None:
    """Drop the view's staged changes and conflicts."""
    from mapctl import render

    session.call("view_abort", view=session.view)
    render.line(f"view {session.view} aborted")


@view.command("list")
@json_option
@pass_session
def view_list(session: Session, as_json: bool) -> None:
    """List the open views."""
    from mapctl import render

    info = session.call("view_list")
    if as_json:
        render.emit_json(info)
    else:
        render.records(
            "views", info["views"], ["name", "begin_time", "isolation", "staged", "conflicts"]
        )


@click.command("status")
@json_option
@pass_session
def status(session: Session, as_json: bool) -> None:
    """Show the view, its begin time, staged changes and conflicts."""
    from mapapi import mapctl_in
    from mapctl import render

    info = session.call("status", view=session.view)
    if as_json:
        render.emit_json(info)
        return
    if not info["open"]:
        render.line(f"view {session.view}: not open (now = {info['now']}); `set` opens it")
        return
    render.line(f"view {session.view} at time {info['begin_time']} (now = {info['now']})")
    render.records("staged changes", info["staged"], ["op", "table", "id"])
    if info["conflicts"]:
        count = len(info["conflicts"])
        hint = f"run `{mapctl_in(session.view)} diff`"
        render.line(f"{count} unresolved conflict(s): {hint}", "yellow")


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
    from mapctl import render

    if len(args) > 2:
        raise click.UsageError("expected TABLE [ID] DATA; quote DATA as one argument")
    info = session.call(
        "set",
        view=session.view,
        table=table_name,
        data=_read_data(args[-1]),
        item=args[0] if len(args) == 2 else None,
        chunk=chunk,
    )
    if as_json:
        render.emit_json(info)
    else:
        render.line(info["id"])


@click.command("get")
@click.argument("table_name", metavar="TABLE")
@click.argument("item", metavar="ID")
@click.option("--at", "at", type=int, help="Read at this logical time (ignores the view).")
@json_option
@pass_session
def get_item(session: Session, table_name: str, item: str, at: int | None, as_json: bool) -> None:
    """Print one item's fields (the view's snapshot plus its staged changes)."""
    from mapctl import render

    info = session.call("get", view=session.view, table=table_name, item=item, at=at)
    if as_json:
        render.emit_json(info["data"])
    else:
        render.pretty_json(info["data"])


@click.command("ls")
@click.argument("table_name", metavar="TABLE")
@click.option("--chunk", "chunk", help="Only this chunk.")
@click.option("--at", "at", type=int, help="List at this logical time (ignores the view).")
@json_option
@pass_session
def ls(session: Session, table_name: str, chunk: str | None, at: int | None, as_json: bool) -> None:
    """List the items of TABLE as the view sees them."""
    from mapctl import render

    info = session.call("ls", view=session.view, table=table_name, chunk=chunk, at=at)
    if as_json:
        render.emit_json({"items": info["items"]})
    else:
        render.table(
            f"items of {table_name} at time {info['time']}",
            ["id", "data"],
            [(r["id"], json.dumps(r["data"])) for r in info["items"]],
        )


@click.command("rm")
@click.argument("table_name", metavar="TABLE")
@click.argument("item", metavar="ID")
@pass_session
def rm(session: Session, table_name: str, item: str) -> None:
    """Stage the removal of an item."""
    from mapctl import render

    info = session.call("rm", view=session.view, table=table_name, item=item)
    render.line(f"staged removal of {info['id']}")


def call_committing(session: Session, as_json: bool, name: str, **args: Any) -> Any:
    """Run operation `name`, which commits the session's view; on a conflict, print
    the view's conflicts first with `as_json` (exit 3 follows, as for `commit`)."""
    from mapapi import ConflictError
    from mapctl import render

    try:
        return session.call(name, view=session.view, **args)
    except ConflictError:
        if as_json:
            render.emit_json({"conflicts": session.call("diff", view=session.view)["conflicts"]})
        raise


@click.command("commit")
@click.option("-m", "--message", default="", help="The commit message.")
@json_option
@pass_session
def commit(session: Session, message: str, as_json: bool) -> None:
    """Commit the view's staged changes. Exits 3 on conflict; the conflicts stay in the view."""
    from mapctl import render

    info = call_committing(session, as_json, "commit", message=message)
    if as_json:
        render.emit_json(info)
    elif info["commit"] is not None:
        stamp = f"[{info['commit'][:8]}] time {info['time']}"
        render.line(f"{stamp}: {message or '(no message)'}", "green")
    else:
        render.line(f"nothing to write; view {session.view} closed")


def _staged(info: dict[str, Any]) -> dict[str, Any]:
    """From a `diff` result: item -> what is staged for it now (None: a removal)."""
    return {ch["id"]: ch["ours"] for ch in info["changes"]}


def _show_conflict(c: dict[str, Any], staged: dict[str, Any]) -> None:
    """One conflict, with "ours" being what is staged now if the user staged an
    edit after the conflict (that is what `resolve --ours` keeps)."""
    from mapctl import render

    ours = ("ours (staged)", staged[c["id"]]) if c["id"] in staged else ("ours", c["ours"])
    sides = {"base": c["base"], ours[0]: ours[1], "theirs": c["theirs"]}
    render.side_by_side(f"conflict {c['table']} {c['id']}", sides, conflict=True)


@click.command("diff")
@json_option
@pass_session
def diff(session: Session, as_json: bool) -> None:
    """Show the staged changes, and the conflicts after a failed commit."""
    from mapctl import render

    info = session.call("diff", view=session.view)
    if as_json:
        render.emit_json(info)
        return
    if not info["changes"] and not info["conflicts"]:
        render.line(f"view {session.view}: nothing staged")
    for ch in info["changes"]:
        sides = {"base": ch["base"], "ours": ch["ours"]}
        render.side_by_side(f"{ch['op']} {ch['table']} {ch['id']}", sides)
    for c in info["conflicts"]:
        _show_conflict(c, _staged(info))


def _pick(conflict: dict[str, Any], staged: dict[str, Any]) -> tuple[str, Any]:
    """Ask how to settle one conflict on a TTY: ours, theirs, edit or skip."""
    _show_conflict(conflict, staged)
    answer = click.prompt(
        "keep [o]urs, [t]heirs, [e]dit, [s]kip",
        type=click.Choice(["o", "t", "e", "s"]),
        default="s",
    )
    item = conflict["id"]
    if answer == "t" and item in staged:
        # Theirs would drop the user's own merge: only on a second, explicit yes.
        asked = f"discard the edit of {item} staged after the conflict?"
        return ("theirs", None) if click.confirm(asked, default=False) else ("skip", None)
    if answer != "e":
        return {"o": "ours", "t": "theirs", "s": "skip"}[answer], None
    ours = staged[item] if item in staged else conflict["ours"]
    start = ours if ours is not None else conflict["theirs"]
    text = click.edit(json.dumps(start, indent=2) + "\n", extension=".json")
    if text is None:
        return "skip", None
    try:
        return "edit", json.loads(text)
    except json.JSONDecodeError as exc:
        raise click.BadParameter(f"the edited text is not JSON: {exc}") from exc


def _ask_each(session: Session, info: dict[str, Any], items: tuple[str, ...]) -> list[str]:
    """Settle the conflicts (those of `items`, if any) one by one on a terminal."""
    wanted = [session.call("match_conflict", view=session.view, text=t) for t in items]
    staged, resolved = _staged(info), []
    for conflict in info["conflicts"]:
        if wanted and conflict["id"] not in wanted:
            continue
        choice, fields = _pick(conflict, staged)
        if choice == "skip":
            continue
        # A staged edit was in view when the user chose (confirmed, or edited
        # from it), so it may go; one staged meanwhile elsewhere is still refused.
        result = session.call(
            "resolve",
            view=session.view,
            side="theirs" if choice == "theirs" else "ours",
            items=[conflict["id"]],
            edited={conflict["id"]: fields} if choice == "edit" else None,
            force=conflict["id"] in staged,
        )
        resolved += result["resolved"]
    return resolved


@click.command("resolve")
@click.argument("items", nargs=-1, metavar="[ID ...]")
@click.option("--ours", "side", flag_value="ours", help="Keep our side: what the view stages now.")
@click.option("--theirs", "side", flag_value="theirs", help="Keep their side.")
@click.option(
    "--force", is_flag=True, help="Also discard edits staged after the conflict (with --theirs)."
)
@json_option
@pass_session
def resolve(
    session: Session, items: tuple[str, ...], side: str | None, force: bool, as_json: bool
) -> None:
    """Settle conflicts (all, or the IDs given). On a TTY with neither flag, ask per conflict.

    An edit staged after the conflict is what --ours keeps; --theirs refuses to
    discard it unless --force is given.
    """
    from mapapi import UsageError, ViewClosedError
    from mapctl import render

    info = session.call("diff", view=session.view)
    if not info["conflicts"]:
        raise ViewClosedError(f"view {session.view!r} has no conflicts to resolve")
    if side in ("ours", "theirs"):
        result = session.call(
            "resolve", view=session.view, side=side, items=list(items), force=force
        )
    elif sys.stdin.isatty():
        resolved = _ask_each(session, info, items)
        result = {"resolved": resolved, "remaining": len(info["conflicts"]) - len(resolved)}
    else:
        raise UsageError("say --ours or --theirs (no terminal to ask on)")
    if as_json:
        render.emit_json(result)
    else:
        done, left = len(result["resolved"]), result["remaining"]
        render.line(f"resolved {done} conflict(s); {left} left", "green")


def register(cli: click.Group) -> None:
    """Add this module's commands to `cli`."""
    for command in (view, status, set_item, get_item, ls, rm, commit, diff, resolve):
        cli.add_command(command)
