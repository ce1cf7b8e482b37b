"""`query-bbox`: find (and load) the chunks and missions in a region."""

from __future__ import annotations

from typing import Any

import click

from mapctl.commands.maps import frame_option
from mapctl.session import Session, json_option, pass_session


@click.command(
    "query-bbox",
    context_settings={"ignore_unknown_options": True},  # negative coordinates are no options
)
@click.argument("bbox", nargs=6, type=float, metavar="XMIN YMIN ZMIN XMAX YMAX ZMAX")
@click.option("--table", "-t", help="Only chunks of this table.")
@click.option(
    "--load",
    is_flag=True,
    help="Participate in every chunk found that is not held here, and in the chunks of "
    "the missions found that lie in the box: their tiles there, with their edges.",
)
@frame_option("The box is", "in the missions' own frames, or in")
@json_option
@pass_session
def query_bbox(
    session: Session,
    bbox: tuple[float, ...],
    table: str | None,
    load: bool,
    frame: str,
    as_json: bool,
) -> None:
    """List the chunks and missions whose box overlaps the box, with their holders.

    The box is in metres, in the missions' own frames (a mission's place in the
    world frame, a `frames` chunk, lies at its world box: it is found with
    --frame world, which then loads the tiles whose box, moved to the world,
    overlaps). Off the network only the chunks held here are searched; with a
    running peer the swarm's spatial index is.
    A box partly outside the index's bounds is clamped; one fully outside
    matches nothing. With --json, --load adds "loaded": the chunks fetched,
    and "items" and "bytes": the rows fetched and their payloads' size.
    """
    from mapctl import render

    args: dict[str, Any] = {"bbox": list(bbox), "table": table}
    if load:
        with render.transfer("loading the chunks in the box") as show:
            info: dict[str, Any] = session.call_with_progress(
                "load_bbox",
                {**args, "frame": frame},
                ("load_progress", args),
                lambda state: show(state["loaded"], state["of"]),
            )
        if not as_json:
            for c in info["loaded"] if session.verbose else ():  # a mission has many tiles
                items = f"{c['items']} item{'' if c['items'] == 1 else 's'}"
                render.note(f"loaded chunk {c['chunk']} ({c['table']}, {items})")
            if info["loaded"]:
                size = render.size_text(info["bytes"])
                render.note(f"loaded {len(info['loaded'])} chunks: {info['items']} items, {size}")
    else:
        places = frame == "world"  # a mission's place lies at its box in the world frame
        info = session.call("query_bbox", **{**args, "table": "frames" if places else table})
        if not places and table != "frames":
            info["results"] = [r for r in info["results"] if r["table"] != "frames"]
    results = info["results"]
    if as_json:
        render.emit_json(info)
        return
    if not results:
        render.line("nothing found in that box")
        return
    render.table(
        "chunks in the box",
        ["chunk", "table", "missions", "bbox", "holders", "here"],
        [
            (
                r["chunk"][:8],
                r["table"],
                ", ".join(r["missions"]) or "-",
                render.box_text(r["bbox"]),
                ", ".join(_holder(h, session.verbose) for h in r["holders"]) or "?",
                "yes" if r["held"] else "no",
            )
            for r in results
        ],
        no_wrap=["bbox"],
    )


def _holder(holder: dict[str, str], verbose: bool) -> str:
    """A holder by name (its short id too with -v); by short id if its name is unknown."""
    short = holder["id"][:8]
    if not holder["name"]:
        return short
    return f"{holder['name']} ({short})" if verbose else holder["name"]


def register(cli: click.Group) -> None:
    """Add this module's commands to `cli`."""
    cli.add_command(query_bbox)
