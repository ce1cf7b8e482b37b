"""`bench ...`: measurements (never assertions)."""

from __future__ import annotations

from typing import Any

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


_DIR_OPTION = click.option(
    "--dir",
    "directory",
    type=click.Path(file_okay=False, exists=True),
    help="Create the peers' scratch repositories here (default: the system temp folder).",
)
_UVLOOP_OPTION = click.option(
    "--uvloop", "use_uvloop", is_flag=True, help="Run every peer's event loop on uvloop."
)


def _render(title: str, result: dict[str, Any], as_json: bool) -> None:
    from mapctl import render

    if as_json:
        render.emit_json(result)
        return
    rows = [(k, v) for k, v in result.items() if not isinstance(v, dict | list)]
    render.table(title, ["measure", "value"], rows)


@bench.command("viewtest")
@click.option(
    "--peers", "-p", default=4, show_default=True, type=click.IntRange(1, 32), help="Processes."
)
@click.option(
    "-n", "n", default=200, show_default=True, type=click.IntRange(1), help="Increments per peer."
)
@click.option("--a0", default=0, show_default=True, help="The counter's first value.")
@_DIR_OPTION
@_UVLOOP_OPTION
@json_option
def bench_viewtest(
    peers: int, n: int, a0: int, directory: str | None, use_uvloop: bool, as_json: bool
) -> None:
    """Paper Algorithm 1: P peer processes each increment one counter N times.

    Every peer retries on conflict; afterwards every peer must read a0 + P*N
    and hold the same commit log, or the command fails (exit 1).
    """
    from mapapi.bench.swarm import check_viewtest, viewtest

    result = viewtest(peers, n, a0=a0, directory=directory, use_uvloop=use_uvloop)
    _render(f"bench viewtest: {peers} peers x {n}", result, as_json)
    check_viewtest(result)


@bench.command("commit")
@click.option(
    "--holders",
    "-k",
    default=3,
    show_default=True,
    type=click.IntRange(1, 32),
    help="Peer processes holding the chunk (the writer included).",
)
@click.option(
    "-n", "n", default=500, show_default=True, type=click.IntRange(1), help="Timed commits."
)
@click.option(
    "--writer",
    type=click.Choice(["other", "arbiter"]),
    default="other",
    show_default=True,
    help="Commit from a holder that is not the arbiter (one more round trip), or from it.",
)
@_DIR_OPTION
@_UVLOOP_OPTION
@json_option
def bench_commit(
    holders: int, n: int, writer: str, directory: str | None, use_uvloop: bool, as_json: bool
) -> None:
    """Uncontended commit latency: one writer, a chunk held by K peer processes."""
    from mapapi.bench.swarm import commit_latency

    result = commit_latency(
        holders,
        n,
        writer="arbiter" if writer == "arbiter" else "other",
        directory=directory,
        use_uvloop=use_uvloop,
    )
    _render(f"bench commit: {holders} holders", result, as_json)


@bench.command("lookup")
@click.option(
    "--peers",
    "-p",
    "peers",
    multiple=True,
    type=click.IntRange(1, 256),
    help="Chord nodes on the ring (repeat for several rings; default 32).",
)
@click.option("--sweep", is_flag=True, help="Also run N = 8, 16, 32, 64 and 128.")
@click.option(
    "--lookups",
    "-n",
    default=1000,
    show_default=True,
    type=click.IntRange(1),
    help="Timed lookups per ring, each from a random node.",
)
@click.option(
    "--seed", default=0, show_default=True, help="Seeds node ids, joins and keys (hops repeat)."
)
@click.option(
    "--plot",
    "plot",
    type=click.Path(dir_okay=False),
    help="Also write a PNG of hops and latency against N (needs matplotlib).",
)
@json_option
def bench_lookup(
    peers: tuple[int, ...],
    sweep: bool,
    lookups: int,
    seed: int,
    plot: str | None,
    as_json: bool,
) -> None:
    """Chord lookups on a ring of N nodes in this process: hops and latency.

    Every answer is checked against a sorted-ring oracle; a wrong answer or a
    failed lookup counts in `errors`. With --json, one object per ring, one per
    line.
    """
    from mapapi.bench.lookup import SWEEP, environment, measure_lookups

    sizes = sorted({*peers, *SWEEP}) if sweep else list(dict.fromkeys(peers or (32,)))
    machine = environment()  # before the runs, whose own load would count otherwise
    results = []
    for size in sizes:
        result = measure_lookups(size, lookups, seed=seed)
        _render(f"bench lookup: {size} peers", result, as_json)
        results.append(result)
    if plot:
        from mapapi.bench.plot import plot_lookup

        plot_lookup(results, plot, machine)


@bench.command("plot")
@click.argument("kind", type=click.Choice(["viewtest", "commit"]))
@click.argument("results", nargs=-1, required=True, type=click.Path(dir_okay=False, exists=True))
@click.option(
    "-o", "--output", required=True, type=click.Path(dir_okay=False), help="The PNG to write."
)
def bench_plot(kind: str, results: tuple[str, ...], output: str) -> None:
    """Plot JSON results (one `--json` object per line in RESULTS) as a PNG.

    viewtest: commits/s and aborts per commit against peers; commit: p50/p99
    latency and messages per commit against holders. Needs matplotlib (the
    `dev` extra).
    """
    from mapapi.bench.plot import load_results, plot_commit, plot_viewtest

    rows = load_results(results)
    (plot_viewtest if kind == "viewtest" else plot_commit)(rows, output)


def register(cli: click.Group) -> None:
    """Add this module's commands to `cli`."""
    cli.add_command(bench)
