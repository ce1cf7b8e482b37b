"""`demo`: a local swarm of peer processes builds the tunnels map (`make demo`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import click

from mapctl.session import json_option


def _xyz(values: list[float]) -> str:
    return "(" + ", ".join(f"{v:.2f}" for v in values) + ")"


@click.command("demo")
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    default=Path("mapapi-demo"),
    show_default=True,
    help="Where the PNGs of the map and the query go (created).",
)
@click.option(
    "--peers", type=click.IntRange(3, 4), default=4, show_default=True, help="Peer processes."
)
@json_option
def demo(out: Path, peers: int, as_json: bool) -> None:
    """Run a swarm of peer processes that build one map together, then stop it.

    The peers (in a temporary folder) each import some robots' missions of the
    Kimera-Multi tunnels set; one finds and loads the others' missions with a
    box query; two edit the same vertex, and the conflict is resolved. Prints
    a summary (--json: as JSON) and writes PNGs of the map and the query to
    --out. Every peer process is stopped at the end, also on Ctrl-C or an error.
    """
    from mapbench.demo import run_demo
    from mapctl import render

    with render.steps() as show:
        summary = run_demo(out, peers, show)
    if as_json:
        render.emit_json(summary)
    else:
        _render(summary)


def _render(summary: dict[str, Any]) -> None:
    from mapctl import render

    render.table(
        "peers",
        ["peer", "pid", "imported", "chunks", "commits", "sent", "received"],
        [
            (
                p["name"],
                p["pid"],
                ", ".join(n.removeprefix("tunnels-") for n in p["imported"]),
                p["chunks"],
                p["commits"],
                render.size_text(p["sent"]["bytes"]),
                render.size_text(p["received"]["bytes"]),
            )
            for p in summary["peers"]
        ],
    )
    query = summary["query"]
    render.line(
        f"{query['peer']} asked for the box {' '.join(f'{v:g}' for v in query['bbox'])}: "
        f"{len(query['found'])} missions, {query['loaded_chunks']} chunks loaded "
        f"({render.size_text(query['bytes_received'])}) in {query['seconds']:.2f} s"
    )
    render.table(
        f"missions on {query['peer']} after the query",
        ["mission", "vertices", "edges", "tiles", "holders", "complete"],
        [
            (
                m["name"],
                m["vertices"],
                m["edges"],
                f"{m['tiles']} of {m['of_tiles']}",
                ", ".join(m["holders"]),
                m["complete"],
            )
            for m in query["missions"]
        ],
    )
    clash = summary["conflict"]
    first, second = clash["peers"]
    render.line(
        f"{first} and {second} both moved vertex {clash['index']} of {clash['mission']} "
        f"from {_xyz(clash['base'])}: {first} to {_xyz(clash['first'])}, "
        f"{second} to {_xyz(clash['second'])}. {second}'s commit conflicted; resolved with "
        f"the mean {_xyz(clash['resolved'])}, which both read back: {clash['agree']}"
    )
    align = summary["align"]
    render.line(
        f"{align['peer']} aligned {len(align['missions'])} missions in the world frame of "
        f"{align['anchor']}: {align['inliers']} of {align['edges']} inter-robot edges kept, their "
        f"RMS {align['rms_before']['metres']:.1f} m before, {align['rms_after']['metres']:.2f} m "
        f"after; every peer's watch received the places "
        f"(the last {max(align['seen'].values()):.2f} s after the commit)"
    )
    timings, moved = summary["timings"], summary["bytes_by_step"]
    render.table(
        "steps",
        ["step", "seconds", "bytes sent"],
        [
            (s, f"{t:.2f}", render.size_text(moved[s]) if s in moved else "")
            for s, t in timings.items()
        ],
    )
    render.line(
        f"{len(summary['peers'])} peers, {summary['chunks']} chunks, {summary['commits']} "
        f"commits, {render.size_text(summary['bytes_moved'])} moved in {timings['total']:.1f} s",
        "bold",
    )
    render.line(
        f"pictures in {summary['out']}: {Path(summary['pngs']['map']).name}, "
        f"{Path(summary['pngs']['query']).name}",
        "green",
    )


def register(cli: click.Group) -> None:
    """Add this module's commands to `cli`."""
    cli.add_command(demo)
