"""`init`, `table ...` and `chunk ...`."""

from __future__ import annotations

from pathlib import Path

import click

from mapctl.session import Session, json_option, pass_session


@click.command("init")
@click.argument("path", type=click.Path(file_okay=False, path_type=Path), default=".")
@click.option("--name", help="A name for this peer (default: the folder's name).")
@json_option
def init(path: Path, name: str | None, as_json: bool) -> None:
    """Create an empty map repository in PATH (default: here)."""
    from mapapi import Repository
    from mapctl import render

    repo = Repository.init(path, name)
    info = {"path": str(repo.root), "name": repo.config.name, "peer_id": repo.config.peer_id}
    if as_json:
        render.emit_json(info)
    else:
        render.line(f"Initialised empty map repository in {repo.meta_dir}")


@click.group("table")
def table() -> None:
    """Create and list tables."""


@table.command("create")
@click.argument("name")
@click.option(
    "--type",
    "type_name",
    required=True,
    help="Full protobuf message name, e.g. google.protobuf.Struct or mapapi.v1.Counter.",
)
@json_option
@pass_session
def table_create(session: Session, name: str, type_name: str, as_json: bool) -> None:
    """Create table NAME holding messages of --type."""
    from mapctl import render

    descriptor = session.run(session.peer.create_table(name, type_name))
    if as_json:
        render.emit_json({"name": descriptor.name, "type": descriptor.type_name})
    else:
        render.line(f"created table {descriptor.name} ({descriptor.type_name})")


@table.command("list")
@json_option
@pass_session
def table_list(session: Session, as_json: bool) -> None:
    """List the tables with their chunk and item counts."""
    from mapctl import render

    chunks = session.peer.chunks()
    rows = [
        {
            "name": name,
            "type": type_name,
            "chunks": sum(1 for c in chunks if c.table == name),
            "items": sum(c.items for c in chunks if c.table == name),
        }
        for name, type_name in session.peer.store.tables().items()
    ]
    if as_json:
        render.emit_json({"tables": rows})
    else:
        render.table("tables", ["name", "type", "chunks", "items"], [r.values() for r in rows])


@click.group("chunk")
def chunk() -> None:
    """Create and list chunks (the unit of replication)."""


@chunk.command("create")
@click.argument("table_name", metavar="TABLE")
@json_option
@pass_session
def chunk_create(session: Session, table_name: str, as_json: bool) -> None:
    """Create an empty chunk of TABLE held by this peer."""
    from mapctl import render

    chunk_id = session.run(session.peer.create_chunk(table_name))
    if as_json:
        render.emit_json({"id": chunk_id, "table": table_name})
    else:
        render.line(chunk_id)


@chunk.command("list")
@click.option("--table", "table_name", help="Only chunks of this table.")
@json_option
@pass_session
def chunk_list(session: Session, table_name: str | None, as_json: bool) -> None:
    """List the chunks this peer holds."""
    from mapctl import render

    rows = [
        {"id": c.id, "table": c.table, "items": c.items} for c in session.peer.chunks(table_name)
    ]
    if as_json:
        render.emit_json({"chunks": rows})
    else:
        render.table("chunks", ["id", "table", "items"], [r.values() for r in rows])


def register(cli: click.Group) -> None:
    """Add this module's commands to `cli`."""
    for command in (init, table, chunk):
        cli.add_command(command)
