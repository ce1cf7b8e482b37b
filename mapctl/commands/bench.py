"""`bench ...`: measurements (never assertions)."""

from __future__ import annotations

import click

from mapctl.session import json_option


@click.group("bench")
def bench() -> None:
    """Measure performance; figures go to docs/benchmarks.md."""


@bench.command("local")
@click.option("-n", "commits", default=500, show_default=True, help="Commits per measurement.")
@click.option(
    "--dir",
    "directory",
    type=click.Path(file_okay=False, exists=True),
    help="Create the scratch repository here (default: the system temp folder).",
)
@json_option
def bench_local(commits: int, directory: str | None, as_json: bool) -> None:
    """Single-peer figures: commits/s, past-time reads/s, CLI startup."""
    from mapapi.bench.local import run_local
    from mapctl import render

    result = run_local(commits, directory)
    if as_json:
        render.emit_json(result)
    else:
        render.table("bench local", ["measure", "value"], sorted(result.items()))


def register(cli: click.Group) -> None:
    """Add this module's commands to `cli`."""
    cli.add_command(bench)
