"""The swarm: `peer start|stop|status`, `peers`, `join`, `clone`, `chunk participate|leave`."""

from __future__ import annotations

import logging
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from mapctl.session import Session, json_option, pass_session

if TYPE_CHECKING:
    from mapapi import PeerRecord, Repository


_LISTEN_HELP = (
    "The swarm endpoint; port 0 picks a free port, and tcp://0.0.0.0:PORT listens on "
    "every interface (for peers on other machines)."
)


def _repo(session: Session) -> Repository:
    from mapapi import Repository

    return Repository.find(session.path)


def _announce(record: PeerRecord, as_json: bool) -> None:
    """Print what scripts read from `peer start`: the address, or its JSON."""
    from mapctl import render

    if as_json:
        render.emit_json({"id": record.id, "address": record.address, "join": record.join})
    else:
        render.line(record.address)
    sys.stdout.flush()


@click.group("peer")
def peer() -> None:
    """Run this repository's peer: the daemon other peers and `mapctl` talk to."""


@peer.command("start")
@click.option("--listen", default="tcp://127.0.0.1:0", show_default=True, help=_LISTEN_HELP)
@click.option(
    "--join", "joins", multiple=True, metavar="ADDR", help="Join the swarm through ADDR (repeat)."
)
@click.option(
    "--advertise",
    metavar="ADDR",
    help="The address to tell other peers (default: the bound one; a 0.0.0.0 host "
    "becomes this machine's address on the route to the first --join peer).",
)
@click.option("--detach", is_flag=True, help="Run in the background; return once it serves.")
@json_option
@pass_session
def peer_start(
    session: Session,
    listen: str,
    joins: tuple[str, ...],
    advertise: str | None,
    detach: bool,
    as_json: bool,
) -> None:
    """Start the peer: print the address others pass to `--join`, then serve.

    With --json print {"id", "address", "join"}. In the foreground it serves until
    Ctrl-C (or `mapctl peer stop`); with --detach it returns once the peer serves.
    """
    from mapapi import check_address, run_daemon, start_daemon
    from mapctl import render

    repo = _repo(session)
    for address in (listen, *joins, *([advertise] if advertise else [])):
        check_address(address)
    if detach:
        record = start_daemon(repo, listen, joins, advertise=advertise, verbose=session.verbose)
        _announce(record, as_json)
        render.note(
            f"peer {record.name} runs in the background (pid {record.pid}); "
            f"log: {repo.log_path}; `mapctl peer stop` stops it"
        )
        return
    logging.basicConfig(
        level=logging.DEBUG if session.verbose else logging.INFO,
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )

    def ready(record: PeerRecord) -> None:
        _announce(record, as_json)
        if not as_json:
            render.note(f"peer {record.name} serves (pid {record.pid}); Ctrl-C stops it")

    run_daemon(repo, listen, joins, advertise=advertise, ready=ready)


@peer.command("stop")
@json_option
@pass_session
def peer_stop(session: Session, as_json: bool) -> None:
    """Stop the running peer gracefully (it says goodbye to the swarm)."""
    from mapapi import stop_daemon
    from mapctl import render

    repo = _repo(session)
    stale = repo.stale_peer_record()
    record = stop_daemon(repo)
    if as_json:
        render.emit_json(
            {
                "stopped": record is not None,
                "pid": record.pid if record else None,
                "id": record.id if record else None,
            }
        )
    elif record is not None:
        render.line(f"stopped peer {record.name} (pid {record.pid})")
    elif stale is not None:
        render.line(f"no peer runs on {repo.root} (removed the stale pid file of {stale.pid})")
    else:
        render.line(f"no peer runs on {repo.root}")


@peer.command("status")
@json_option
@pass_session
def peer_status(session: Session, as_json: bool) -> None:
    """Show whether the peer runs, its id, addresses and the swarm's members."""
    from mapctl import render

    record = _repo(session).running_peer()
    info: dict[str, Any] = {"running": False}
    if record is not None:
        info = {"running": True, **session.call("peer_status"), "control": record.control}
    if as_json:
        render.emit_json(info)
    elif not info["running"]:
        render.line("no peer runs here; `mapctl peer start --detach` starts one")
    else:
        render.line(f"peer {info['name']} {info['id']} (pid {info['pid']})")
        render.line(f"  join:    {info['join']}")
        render.line(f"  control: {info['control']}")
        render.line(f"  swarm:   {len(info['members'])} member(s), {info['chunks']} chunk(s) here")
        if (lag := info.get("loop_lag_ms")) is not None:
            render.line(
                f"  loop:    late by p50 {lag['p50']} ms, p99 {lag['p99']} ms, "
                f"max {lag['max']} ms over the last minute"
            )
        render.history_warnings(info)


def _ago(seconds: float | None) -> str:
    return "never" if seconds is None else f"{seconds:.1f} s ago"


@click.command("peers")
@json_option
@pass_session
def peers(session: Session, as_json: bool) -> None:
    """List the other peers of the swarm: id, address, last seen, shared chunks."""
    from mapctl import render

    info = session.call("peers")
    if as_json:
        render.emit_json(info)
        return
    render.table(
        "peers",
        ["id", "name", "address", "last seen", "shared chunks"],
        [
            (p["id"][:8], p["name"], p["address"], _ago(p["last_seen"]), len(p["shared_chunks"]))
            for p in info["peers"]
        ],
    )


@click.command("join")
@click.argument("address", metavar="ADDR")
@json_option
@pass_session
def join(session: Session, address: str, as_json: bool) -> None:
    """Connect the running peer to the swarm of the peer at ADDR."""
    from mapctl import render

    info = session.call("join", address=address)
    if as_json:
        render.emit_json(info)
    else:
        render.line(f"joined the swarm through {address}: {len(info['members'])} peer(s)")


def participate_with_progress(session: Session, chunk_id: str) -> dict[str, Any]:
    """Run `participate`, showing a progress bar once the chunk comes in several parts."""
    from mapctl import render

    with render.transfer(f"fetching chunk {chunk_id[:8]} with its history") as show:
        result: dict[str, Any] = session.call_with_progress(
            "participate",
            {"chunk": chunk_id},
            ("participate_progress", {"chunk": chunk_id}),
            lambda state: show(state["received"], state["parts"]),
        )
    return result


@click.command("participate")
@click.argument("chunk_id", metavar="ID")
@json_option
@pass_session
def chunk_participate(session: Session, chunk_id: str, as_json: bool) -> None:
    """Replicate chunk ID here: fetch it with its history, then receive every commit."""
    from mapctl import render

    info = participate_with_progress(session, chunk_id)
    if as_json:
        render.emit_json(info)
    else:
        render.line(
            f"participating in chunk {info['chunk']} ({info['table']}, {info['items']} items, "
            f"{len(info['holders'])} holders)",
            "green",
        )


@click.command("leave")
@click.argument("chunk_id", metavar="ID")
@click.option("--force", is_flag=True, help="Leave even as the last holder (drops the data).")
@json_option
@pass_session
def chunk_leave(session: Session, chunk_id: str, force: bool, as_json: bool) -> None:
    """Stop replicating chunk ID (the last holder needs --force)."""
    from mapctl import render

    info = session.call("chunk_leave", chunk=chunk_id, force=force)
    if as_json:
        render.emit_json(info)
    else:
        render.line(f"left chunk {info['chunk']}")


def _chunk_choice(values: tuple[str, ...]) -> list[str] | None:
    """The chunk ids `--chunks` names; None means all."""
    from mapapi import UsageError

    specs = [s.strip() for v in values for s in v.split(",") if s.strip()] or ["all"]
    if len(specs) > 1 and {"all", "none"} & set(specs):
        raise UsageError("--chunks takes all, none, or chunk ids; not a mix")
    if specs == ["all"]:
        return None
    return [] if specs == ["none"] else specs


@click.command("clone")
@click.argument("address", metavar="ADDR")
@click.argument("directory", metavar="DIR", type=click.Path(file_okay=False, path_type=Path))
@click.option(
    "--chunks",
    "chunks",
    multiple=True,
    metavar="all|none|ID",
    help="Which chunks to replicate: all (default), none, or ids (repeat, or comma-separated).",
)
@click.option("--listen", default="tcp://127.0.0.1:0", show_default=True, help=_LISTEN_HELP)
@click.option("--name", help="A name for the new peer (default: the folder's name).")
@json_option
@pass_session
def clone(
    session: Session,
    address: str,
    directory: Path,
    chunks: tuple[str, ...],
    listen: str,
    name: str | None,
    as_json: bool,
) -> None:
    """Make DIR a new peer of the swarm at ADDR: init, start its peer, join, participate.

    DIR may also be a repository `mapctl init` just made (still empty): that is how
    a secure swarm is cloned, since the swarm must trust the new peer's key first.
    """
    from mapapi import clone as clone_into
    from mapctl import render

    wanted = _chunk_choice(chunks)
    with render.chunk_transfers() as show:
        cloned = session.run(
            clone_into(
                address,
                directory,
                chunks=wanted,
                listen=listen,
                name=name,
                verbose=session.verbose,
                progress=show,
            )
        )
    render.cloned(address, cloned.to_json(), cloned.record.name, as_json=as_json)


def register(cli: click.Group) -> None:
    """Add this module's commands to `cli` (and `participate`/`leave` to `chunk`)."""
    for command in (peer, peers, join, clone):
        cli.add_command(command)
    chunk = cli.commands["chunk"]
    assert isinstance(chunk, click.Group), "register the repo commands first"
    chunk.add_command(chunk_participate)
    chunk.add_command(chunk_leave)
