"""`watch`: stream the changes in a region as they are committed (DESIGN §8)."""

from __future__ import annotations

import time

import click

from mapctl.session import Session, json_option, pass_session

POLL_S = 1.0  # the longest a long poll lasts; changes return it at once


@click.command("watch", context_settings={"ignore_unknown_options": True})
@click.option(
    "--bbox",
    nargs=6,
    type=float,
    metavar="XMIN YMIN ZMIN XMAX YMAX ZMAX",
    help="The region (default: the whole spatial index).",
)
@click.option("--table", "-t", help="Only items of this table.")
@click.option(
    "--where",
    "where",
    multiple=True,
    metavar="FIELD=VALUE",
    help="Only items whose top-level FIELD equals VALUE (JSON, else a string); repeatable.",
)
@click.option("--count", "-n", type=click.IntRange(1), help="Exit after K changes.")
@click.option(
    "--timeout",
    type=click.FloatRange(0, min_open=True),
    help="Give up after S seconds: exit 1 if fewer changes than --count (or none) arrived.",
)
@json_option
@pass_session
def watch(
    session: Session,
    bbox: tuple[float, ...] | None,
    table: str | None,
    where: tuple[str, ...],
    count: int | None,
    timeout: float | None,
    as_json: bool,
) -> None:
    """Print the changes other peers (and this one) commit in a region, as they
    happen: one line per changed item, or JSON lines with --json.

    Needs the running peer: it subscribes to the region in the swarm's spatial
    index, and committers push only the matching changes to it. Ctrl-C stops.
    """
    from mapapi import WatchTimeout
    from mapctl import render

    started = session.call(
        "watch_start", bbox=list(bbox) if bbox else None, table=table, where=list(where)
    )
    watch_id = started["watch"]
    seen = 0
    deadline = None if timeout is None else time.monotonic() + timeout
    box = " ".join(f"{v:g}" for v in started["bbox"])
    render.note(f"watching {box}; Ctrl-C stops")  # on stderr: the subscription is active
    show = render.json_line if as_json else render.ChangeRows().add
    try:
        while count is None or seen < count:
            wait = POLL_S if deadline is None else min(POLL_S, deadline - time.monotonic())
            if wait <= 0:
                break
            for change in session.call("watch_next", watch=watch_id, timeout=wait)["changes"]:
                show(change)
                seen += 1
                if count is not None and seen >= count:
                    break
    finally:
        session.call("watch_stop", watch=watch_id)
    if deadline is not None and (seen == 0 or (count is not None and seen < count)):
        wanted = f"{count} change(s)" if count is not None else "a change"
        raise WatchTimeout(f"{seen} change(s) arrived in {timeout:g} s, waited for {wanted}")


def register(cli: click.Group) -> None:
    """Add this module's commands to `cli`."""
    cli.add_command(watch)
