"""`init`, `table ...` and `chunk ...`."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import click

from mapctl.session import Session, json_option, pass_session


@click.command("init")
@click.argument("path", type=click.Path(file_okay=False, path_type=Path), default=".")
@click.option("--name", help="A name for this peer (default: the folder's name).")
@click.option(
    "--bounds",
    nargs=6,
    type=float,
    metavar="XMIN YMIN ZMIN XMAX YMAX ZMAX",
    help="Space the spatial index covers, in metres [default: -1024 -1024 -128 1024 1024 128].",
)
@click.option(
    "--cells",
    nargs=3,
    type=int,
    metavar="NX NY NZ",
    help="Cells of the spatial index along x, y, z [default: 32 32 1].",
)
@click.option(
    "--secure",
    is_flag=True,
    help="Make a secure peer: a keypair and an empty trust list (CurveZMQ). In an "
    "existing open repository, add them and keep its data.",
)
@click.option(
    "--recover",
    is_flag=True,
    help="Rebuild a lost config.toml from the store: the peer id (the holder of every "
    "chunk), its name (its commits), secure if its keys are there.",
)
@click.option(
    "--peer-id",
    metavar="ID",
    help="With --recover: the peer id, when the store cannot tell it.",
)
@json_option
def init(
    path: Path,
    name: str | None,
    bounds: tuple[float, ...] | None,
    cells: tuple[int, int, int] | None,
    secure: bool,
    recover: bool,
    peer_id: str | None,
    as_json: bool,
) -> None:
    """Create an empty map repository in PATH (default: here).

    Every peer of a swarm must use the same spatial index (--bounds, --cells):
    a peer with another one is refused when it joins. A secure peer (--secure)
    talks only to secure peers whose keys it trusts (`mapctl trust add`).
    A repository whose config.toml is lost but whose store holds a map is
    refused; `--recover` rebuilds its config from the store.
    """
    from mapapi import AlreadyInitialisedError, BBox, Repository, SpatialGrid, key_text
    from mapctl import render

    default = SpatialGrid()
    grid = SpatialGrid(
        BBox.from_tuple(bounds) if bounds else default.bounds, cells or default.cells
    )
    if peer_id and not recover:
        raise click.UsageError("--peer-id goes with --recover")
    if recover:
        if secure:
            raise click.UsageError("--recover finds the keys of a secure repository; drop --secure")
        repo, identity = Repository.recover(
            path, name, grid if bounds or cells else None, peer_id=peer_id
        )
        made = (
            f"Recovered the config of the map repository in {{}}: peer id {repo.config.peer_id} "
            f"({identity.how}), name {repo.config.name!r}"
        )
    else:
        try:
            repo = Repository.init(path, name, grid, secure=secure)
            made = f"Initialised empty {'secure ' if secure else ''}map repository in {{}}"
        except AlreadyInitialisedError:
            if not secure or name or bounds or cells:
                raise
            repo = Repository.find(path)
            repo.make_secure()
            made = "Made the map repository in {} secure (its data is kept)"
    security = repo.security()
    info = {
        "path": str(repo.root),
        "name": repo.config.name,
        "peer_id": repo.config.peer_id,
        "spatial": repo.config.spatial.to_config(),
        "secure": security is not None,
        **({"public_key": key_text(security.keys.public)} if security else {}),
    }
    if as_json:
        render.emit_json(info)
        return
    render.line(made.format(repo.meta_dir))
    if recover:
        render.note(
            "the spatial index is not kept in the store: this config has "
            f"{repo.config.spatial.to_config()}; if the swarm uses another, give its "
            "--bounds and --cells (edit [spatial] in config.toml), or joining is refused"
        )
    if security is not None:
        render.note(
            f"public key {info['public_key']}: peers that trust it (`mapctl trust add KEY`) "
            "admit this one"
        )


def replication_option(whose: str) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """`--replication K`: the most voters of {whose} (0, the default: 3)."""
    return click.option(
        "--replication",
        type=click.IntRange(min=0),
        default=0,
        show_default=False,
        metavar="K",
        help=f"The replication factor: the most voters of {whose}; the other holders "
        "are learners, which never hold a commit up. Keep it odd (an even one acts as the "
        "odd number below it). 0, the default: 3.",
    )


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
@replication_option("its chunks' groups, unless a chunk is created with its own")
@json_option
@pass_session
def table_create(
    session: Session, name: str, type_name: str, replication: int, as_json: bool
) -> None:
    """Create table NAME holding messages of --type."""
    from mapctl import render

    info = session.call("table_create", name=name, type_name=type_name, replication=replication)
    if as_json:
        render.emit_json(info)
    else:
        render.line(
            f"created table {info['name']} ({info['type']}, replication {info['replication']})"
        )


@table.command("list")
@json_option
@pass_session
def table_list(session: Session, as_json: bool) -> None:
    """List the tables with their chunk and item counts."""
    from mapctl import render

    info = session.call("table_list")
    if as_json:
        render.emit_json(info)
    else:
        render.records("tables", info["tables"], ["name", "type", "chunks", "items"])


@click.group("chunk")
def chunk() -> None:
    """Create and list chunks (the unit of replication)."""


@chunk.command("create")
@click.argument("table_name", metavar="TABLE")
@replication_option("the chunk's group (default: its table's)")
@json_option
@pass_session
def chunk_create(session: Session, table_name: str, replication: int, as_json: bool) -> None:
    """Create an empty chunk of TABLE held by this peer."""
    from mapctl import render

    info = session.call("chunk_create", table=table_name, replication=replication)
    if as_json:
        render.emit_json(info)
    else:
        render.line(info["id"])


@chunk.command("list")
@click.option("--table", "table_name", help="Only chunks of this table.")
@click.option(
    "--peer",
    "address",
    metavar="ADDR",
    help="List the chunks the peer at ADDR holds (asked over the network), e.g. "
    "tcp://192.168.1.10:7000.",
)
@json_option
@pass_session
def chunk_list(
    session: Session, table_name: str | None, address: str | None, as_json: bool
) -> None:
    """List the chunks this peer (or the peer at --peer ADDR) holds."""
    from mapctl import render

    info = session.call("chunk_list", table=table_name, peer=address)
    if as_json:
        render.emit_json(info)
    elif address is not None:
        render.records("chunks", info["chunks"], ["id", "table", "items"])
    else:  # each holder by short id, with its role in the chunk's group when known
        rows = [
            {**row, "holders": ", ".join(_holder(h, row["roles"].get(h)) for h in row["holders"])}
            for row in info["chunks"]
        ]
        render.records("chunks", rows, ["id", "table", "items", "replication", "holders"])


def _holder(peer: str, role: str | None) -> str:
    return peer[:8] if role is None else f"{peer[:8]} ({role})"


@click.command("fsck")
@click.option(
    "--accept",
    is_flag=True,
    help="Accept a rollback the store went through (the lost commits stay lost): "
    "forget it and record the store as it is now.",
)
@json_option
@pass_session
def fsck(session: Session, accept: bool, as_json: bool) -> None:
    """Check the store: the SQLite file, every payload, every chunk's hash chain, its
    high-water mark (a rolled-back store) and what other holders' chains showed.

    Exits 1 when anything is wrong (after the report), 0 when all is sound."""
    from mapctl import render

    report = session.call("fsck", accept=accept)
    if as_json:
        render.emit_json(report)
    else:
        render.fsck_report(report)
    if not report["ok"]:
        raise SystemExit(1)


def register(cli: click.Group) -> None:
    """Add this module's commands to `cli`."""
    for command in (init, table, chunk, fsck):
        cli.add_command(command)
