"""A secure swarm's keys: `key show` and `trust add|list|remove` (DESIGN §10).

They read and write `.mapapi/curve/` directly, whether or not the peer runs: a
running peer re-reads its trust list at each new connection.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import click

from mapctl.session import Session, json_option, pass_session

if TYPE_CHECKING:
    from mapapi import Security


def _security(session: Session) -> Security:
    from mapapi import Repository, UsageError

    repo = Repository.find(session.path)
    security = repo.security()
    if security is None:
        raise UsageError(
            f"{repo.root} is an open repository (no keys); `mapctl init --secure` in it "
            "makes it secure"
        )
    return security


@click.group("key")
def key() -> None:
    """This peer's public key (secure repositories)."""


@key.command("show")
@json_option
@pass_session
def key_show(session: Session, as_json: bool) -> None:
    """Print this peer's public key: what other peers pass to `trust add`
    (with `--id ID` too when this peer's id is not derived from its key)."""
    from mapapi import key_text
    from mapctl import render

    security = _security(session)
    public = key_text(security.keys.public)
    bound = security.own_id  # None: the id is derived from the key
    if as_json:  # the peer id is derived from the key unless it is named
        render.emit_json({"public_key": public} | ({} if bound is None else {"peer_id": bound}))
    elif bound is None:
        render.line(public)
    else:
        render.line(f"{public} {bound}")
        render.line(
            f"this peer's id is not derived from its key: other peers trust it with "
            f"`mapctl trust add {public} --id {bound}`"
        )


@click.group("trust")
def trust() -> None:
    """The public keys this peer accepts and connects to (secure repositories)."""


@trust.command("add")
@click.argument("keys", metavar="KEY...", nargs=-1, required=True)
@click.option(
    "--id",
    "peer_id",
    metavar="PEER_ID",
    help="The peer id bound to KEY, for a peer whose id is not derived from its key "
    "(as its `mapctl key show` says); it may send as no other.",
)
@json_option
@pass_session
def trust_add(session: Session, keys: tuple[str, ...], peer_id: str | None, as_json: bool) -> None:
    """Trust each KEY (64 hex digits, as `mapctl key show` prints them)."""
    from mapapi import PeerId, UsageError, key_text, parse_key
    from mapctl import render

    security = _security(session)
    parsed = [parse_key(text) for text in keys]  # all valid, or nothing is written
    if peer_id is not None and len(parsed) != 1:
        raise UsageError("--id binds one key: give one KEY with it")
    try:
        bound = PeerId(peer_id) if peer_id is not None else None
    except ValueError as exc:
        raise UsageError(f"--id: {exc}") from None
    rows = [{"key": key_text(k), "added": security.trust.add(k, bound)} for k in parsed]
    if as_json:
        render.emit_json({"keys": rows})
        return
    for row in rows:
        render.line(f"{'trusted' if row['added'] else 'already trusted'}: {row['key']}")


@trust.command("list")
@json_option
@pass_session
def trust_list(session: Session, as_json: bool) -> None:
    """List the trusted keys (this peer's own key is always trusted, and not listed)."""
    from mapapi import key_text
    from mapctl import render

    keys = sorted(key_text(k) for k in _security(session).trust.current())
    if as_json:
        render.emit_json({"trusted": keys})
    else:
        render.table("trusted keys", ["public key"], [(k,) for k in keys])


@trust.command("remove")
@click.argument("key_arg", metavar="KEY")
@json_option
@pass_session
def trust_remove(session: Session, key_arg: str, as_json: bool) -> None:
    """Stop trusting KEY: its new connections are refused (restart the peer to
    also cut the ones open now)."""
    from mapapi import key_text, parse_key
    from mapctl import render

    parsed = parse_key(key_arg)
    removed = _security(session).trust.remove(parsed)
    if as_json:
        render.emit_json({"key": key_text(parsed), "removed": removed})
    else:
        render.line(f"{'no longer trusted' if removed else 'was not trusted'}: {key_text(parsed)}")


def register(cli: click.Group) -> None:
    """Add this module's commands to `cli`."""
    cli.add_command(key)
    cli.add_command(trust)
