"""`bench mapping`: robots streaming their missions through the chunks' Raft groups."""

from __future__ import annotations

from typing import Any

import click

from mapctl.commands.bench_options import DIR_OPTION, UVLOOP_OPTION, measures
from mapctl.session import json_option


def _option(flag: str, short: str, default: object, kind: click.ParamType, text: str) -> Any:
    return click.option(flag, short, default=default, show_default=True, type=kind, help=text)


@click.command("mapping")
@_option("--robots", "-p", 4, click.IntRange(1, 32), "Robot processes.")
@_option("--holders", "-k", 3, click.IntRange(1, 32), "Holders of each chunk (its robot included).")
@_option("--seconds", "-s", 10.0, click.FloatRange(0.1), "How long every robot streams.")
@_option("--batch", "-b", "10:100", click.STRING, "LOW:HIGH vertices per commit (edges follow).")
@_option(
    "--cross", "-x", 0.05, click.FloatRange(0, 1), "Share of inter-robot edges (2-chunk commits)."
)
@click.option(
    "--cross-alone",
    is_flag=True,
    help="Commit each inter-robot edge on its own (else with the robot's other edges).",
)
@click.option("--seed", default=0, show_default=True, help="Seeds the robots' choices.")
@DIR_OPTION
@UVLOOP_OPTION
@json_option
def bench_mapping(
    robots: int,
    holders: int,
    seconds: float,
    batch: str,
    cross: float,
    cross_alone: bool,
    seed: int,
    directory: str | None,
    use_uvloop: bool,
    as_json: bool,
) -> None:
    """P robot processes stream vertices and edges into their own chunks, each
    held by K peers; reports items/s, commit p50/p99 and bytes sent per item.

    Afterwards every holder of every chunk must hold exactly the items its
    writers acknowledged, or the command fails (exit 1).
    """
    from mapbench.mapping import Workload, check_mapping, mapping

    if holders > robots:
        raise click.BadParameter(f"at most --robots ({robots})", param_hint="--holders")
    low, _, high = batch.partition(":")
    try:
        sizes = (int(low), int(high or low))
    except ValueError:
        raise click.BadParameter(f"{batch!r} is not LOW:HIGH", param_hint="--batch") from None
    if not 1 <= sizes[0] <= sizes[1]:
        raise click.BadParameter("need 1 <= LOW <= HIGH", param_hint="--batch")
    workload = Workload(seconds=seconds, batch=sizes, cross=cross, alone=cross_alone, seed=seed)
    result = mapping(robots, holders, workload, directory=directory, use_uvloop=use_uvloop)
    measures(f"bench mapping: {robots} robots, {holders} holders", result, as_json)
    check_mapping(result)


COMMANDS = (bench_mapping,)
"""The commands of this module, which the `bench` group adds."""
