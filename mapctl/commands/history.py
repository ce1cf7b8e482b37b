"""`log` and `show`: the repository's history."""

from __future__ import annotations

import json

import click

from mapctl.session import Session, json_option, pass_session


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
    from mapapi import ItemId
    from mapctl import render, shape

    peer = session.peer
    if item is not None and table_name is not None:
        item_id = ItemId(session.resolve_id("item", item))
        peer.table(table_name)
        rows = []
        for revision in reversed(peer.history(item_id)):
            record = peer.commit_record(revision.commit_id)
            rows.append(
                {
                    "commit": revision.commit_id,
                    "time": revision.update_time,
                    "author": revision.author,
                    "message": record.message if record else "",
                    "data": shape.revision_fields(peer, revision),
                }
            )
        rows = rows[:limit] if limit else rows
        columns = ["commit", "time", "author", "message", "data"]
    else:
        records = peer.log()
        if table_name is not None:
            chunks = {c.id for c in peer.chunks(table_name)}
            records = [r for r in records if chunks & set(r.chunks)]
        rows = [shape.commit(r) for r in records[:limit]]
        columns = ["commit", "time", "author", "message", "chunks"]
    if as_json:
        render.emit_json(rows)
        return
    render.table(
        "log",
        columns,
        [
            [
                v[:8]
                if k in ("commit", "author")
                else json.dumps(v)
                if k == "data"
                else len(v)
                if k == "chunks"
                else v
                for k, v in r.items()
            ]
            for r in rows
        ],
    )


@click.command("show")
@click.argument("commit_ref", metavar="COMMIT")
@json_option
@pass_session
def show(session: Session, commit_ref: str, as_json: bool) -> None:
    """Show one commit and the revisions it wrote."""
    from mapapi import CommitId, UsageError
    from mapapi.history import change_kind
    from mapctl import render, shape

    peer = session.peer
    commit_id = CommitId(session.resolve_id("commit", commit_ref))
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
                "data": shape.revision_fields(peer, revision),
            }
        )
    info = {**shape.commit(record), "changes": changes}
    if as_json:
        render.emit_json(info)
        return
    render.line(f"commit {record.id}  time {record.time}  author {record.author}", "bold")
    render.line(f"    {record.message or '(no message)'}")
    render.table(
        "changes",
        ["op", "table", "id", "data"],
        [(c["op"], c["table"], c["id"], json.dumps(c["data"])) for c in changes],
    )


def register(cli: click.Group) -> None:
    """Add this module's commands to `cli`."""
    cli.add_command(log)
    cli.add_command(show)
