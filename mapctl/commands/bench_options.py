"""What the `bench` commands share (mapctl/commands/bench*.py): options, and how a
benchmark's figures are shown."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import click

DIR_OPTION = click.option(
    "--dir",
    "directory",
    type=click.Path(file_okay=False, exists=True),
    help="Create the peers' scratch repositories here (default: the system temp folder).",
)
UVLOOP_OPTION = click.option(
    "--uvloop", "use_uvloop", is_flag=True, help="Run every peer's event loop on uvloop."
)
SECURE_OPTION = click.option(
    "--secure", is_flag=True, help="A secure swarm: CurveZMQ between peers that trust each other."
)


def measures(title: str, result: dict[str, Any], as_json: bool) -> None:
    """Show a benchmark's figures (`render.measures`; rich loads only now)."""
    from mapctl import render

    render.measures(title, result, as_json)


def repeatable(flag: str, dest: str, kind: click.ParamType, text: str) -> Any:
    """An option that may be given several times (`dest` collects a tuple)."""
    return click.option(flag, flag[1:3], dest, multiple=True, type=kind, help=text)


def plot_option(what: str) -> Any:
    """`--plot FILE`: also write a PNG of `what`."""
    return click.option(
        "--plot", type=click.Path(dir_okay=False), help=f"Also write a PNG of {what} (matplotlib)."
    )


def per_run(flag: str, default: int, text: str) -> Any:
    """`-n`: how many timed operations a run makes."""
    return click.option(
        flag, "-n", default=default, show_default=True, type=click.IntRange(1), help=text
    )


SAMPLES_OPTION = click.option(
    "--samples",
    type=click.Path(file_okay=False, exists=True, path_type=Path),
    help="The sample_maps folder (default: the one of this source tree).",
)
