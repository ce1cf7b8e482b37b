"""`log`, `show` and `gc`: the repository's history."""

from __future__ import annotations

import json
from typing import Any

import click

from mapctl.session import Session, json_option, pass_session


def _author(row: dict[str, Any], verbose: bool) -> str:
    """Who committed, for people: "robot1/bob" (name / view; the main view is
    left out), with the short id after it under `-v`."""
    view = row.get("view", "")
    name = f"{row['author_name']}/{view}" if view not in ("", "main") else row["author_name"]
    return f"{name} ({row['author'][:8]})" if verbose else name


def _cell(key: str, row: dict[str, Any], verbose: bool) -> Any:
    """How a log column reads for humans: names, short ids, JSON data, chunk counts."""
    value: Any = row.get(key)
    if key == "author":
        return _author(row, verbose)
    if key == "commit":
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
    """Show commits (newest first), those touching TABLE, or one item's revisions.

    `#` numbers the commits 1..n in commit order; authors show by name, as
    NAME/VIEW for a commit from a named view (ids with -v and in --json)."""
    from mapctl import render

    rows = session.call("log", table=table_name, item=item, limit=limit)
    if as_json:
        render.emit_json(rows)
        return
    last = "data" if item is not None else "chunks"
    # `seq` numbers commits 1..n in order; `time` is Lamport time, which jumps
    # (docs/guide/history.md, "Logical time").
    columns = ["seq", "commit", "time", "author", "message", last]
    cells = [[_cell(k, r, session.verbose) for k in columns] for r in rows]
    render.table("log", ["#", *columns[1:]], cells)


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
    author = _author(info, session.verbose)
    head = f"commit {info['commit']}  #{info['seq']}  time {info['time']}  author {author}"
    render.line(head, "bold")
    render.line(f"    {info['message'] or '(no message)'}")
    render.table(
        "changes",
        ["op", "table", "id", "data"],
        [(c["op"], c["table"], c["id"], json.dumps(c["data"])) for c in info["changes"]],
    )


@click.command("gc")
@click.option(
    "--keep-since",
    metavar="TIME",
    help="Keep what a read at this logical time or later sees (a time, or a commit id: its time).",
)
@click.option(
    "--keep", type=click.IntRange(1), metavar="N", help="Keep each item's N newest revisions."
)
@json_option
@pass_session
def gc(session: Session, keep_since: str | None, keep: int | None, as_json: bool) -> None:
    """Drop old history: the revisions no read at or after a horizon sees.

    Never an item's newest revision, and never what an open view or a running
    transaction may read: the horizon stops at the oldest of them. With neither
    option, `retention = N` under [history] in .mapapi/config.toml gives --keep.
    Each holder compacts its own replicas; `log` keeps every commit record."""
    from mapctl import render

    done = session.call("gc", keep_since=keep_since, keep=keep)
    if as_json:
        render.emit_json(done)
        return
    kept = f", each item's newest {done['keep']} kept" if done["keep"] else ""
    render.line(
        f"dropped {done['revisions']} revision(s) of {done['items']} item(s) "
        f"({render.size_text(done['bytes'])} of payloads) from {done['chunks']} chunk(s)"
    )
    render.line(
        f"horizon: time {done['horizon']} (set by {done['set_by']}){kept}; "
        f"the store holds {render.size_text(done['store_bytes'])} (freed pages are reused)"
    )


def register(cli: click.Group) -> None:
    """Add this module's commands to `cli`."""
    cli.add_command(log)
    cli.add_command(show)
    cli.add_command(gc)
