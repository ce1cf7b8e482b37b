"""`log` and `show`: the repository's history."""

from __future__ import annotations

import json
from typing import Any

import click

from mapctl.session import Session, json_option, pass_session


def _cell(key: str, value: Any) -> Any:
    """How a log column reads for humans: short ids, JSON data, chunk counts."""
    if key in ("commit", "author"):
        return value[:8]
    if key == "data":
        return json.dumps(value)
    if key == "chunks":
        return len(value)
    return value


@click.command("log")
@click.argument("table_name", metavar="[TABLE", required=False)
@click.argument("item", metavar="[ID]]", required=False)
@click.option("-n", "limit", type=int, help="At most this many commits.")
@json_option
@pass_session
def log(
    session: Session, table_name: str | None, item: str | None, limit: int | None, as_json: bool
) -> None:
    """Show commits (newest first), those touching TABLE, or one item's revisions."""
    from mapctl import render

    rows = session.call("log", table=table_name, item=item, limit=limit)
    if as_json:
        render.emit_json(rows)
        return
    last = "data" if item is not None else "chunks"
    columns = ["commit", "time", "author", "message", last]
    render.table("log", columns, [[_cell(k, r[k]) for k in columns] for r in rows])


@click.command("show")
@click.argument("commit_ref", metavar="COMMIT")
@json_option
@pass_session
def show(session: Session, commit_ref: str, as_json: bool) -> None:
    """Show one commit and the revisions it wrote."""
    from mapctl import render

    info = session.call("show", commit=commit_ref)
    if as_json:
        render.emit_json(info)
        return
    render.line(f"commit {info['commit']}  time {info['time']}  author {info['author']}", "bold")
    render.line(f"    {info['message'] or '(no message)'}")
    render.table(
        "changes",
        ["op", "table", "id", "data"],
        [(c["op"], c["table"], c["id"], json.dumps(c["data"])) for c in info["changes"]],
    )


def register(cli: click.Group) -> None:
    """Add this module's commands to `cli`."""
    cli.add_command(log)
    cli.add_command(show)
