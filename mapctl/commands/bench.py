"""`bench ...`: measurements (never assertions)."""

from __future__ import annotations

from pathlib import Path

import click

from mapctl.commands import bench_faults, bench_mapping, bench_maps
from mapctl.commands.bench_options import (
    DIR_OPTION,
    SAMPLES_OPTION,
    SECURE_OPTION,
    UVLOOP_OPTION,
    measures,
    per_run,
    plot_option,
    repeatable,
)
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
    from mapbench.local import run_local
    from mapctl import render

    result = run_local(commits, directory)
    if as_json:
        render.emit_json(result)
    else:
        render.table("bench local", ["measure", "value"], sorted(result.items()))


@bench.command("viewtest")
@click.option(
    "--peers", "-p", default=4, show_default=True, type=click.IntRange(1, 32), help="Processes."
)
@click.option(
    "-n", "n", default=200, show_default=True, type=click.IntRange(1), help="Increments per peer."
)
@click.option("--a0", default=0, show_default=True, help="The counter's first value.")
@DIR_OPTION
@UVLOOP_OPTION
@SECURE_OPTION
@json_option
def bench_viewtest(
    peers: int,
    n: int,
    a0: int,
    directory: str | None,
    use_uvloop: bool,
    secure: bool,
    as_json: bool,
) -> None:
    """Paper Algorithm 1: P peer processes each increment one counter N times.

    Every peer retries on conflict; afterwards every peer must read a0 + P*N
    and hold the same commit log, or the command fails (exit 1).
    """
    from mapbench.swarm import check_viewtest, viewtest

    result = viewtest(peers, n, a0=a0, directory=directory, use_uvloop=use_uvloop, secure=secure)
    measures(f"bench viewtest: {peers} peers x {n}", result, as_json)
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
    type=click.Choice(["follower", "leader"]),
    default="follower",
    show_default=True,
    help="Commit from a holder that does not lead the chunk's group (it forwards to the "
    "leader: one more round trip), or from the leader.",
)
@DIR_OPTION
@UVLOOP_OPTION
@SECURE_OPTION
@json_option
def bench_commit(
    holders: int,
    n: int,
    writer: str,
    directory: str | None,
    use_uvloop: bool,
    secure: bool,
    as_json: bool,
) -> None:
    """Uncontended commit latency: one writer, a chunk held by K peer processes."""
    from mapbench.swarm import commit_latency

    result = commit_latency(
        holders,
        n,
        writer="leader" if writer == "leader" else "follower",
        directory=directory,
        use_uvloop=use_uvloop,
        secure=secure,
    )
    measures(f"bench commit: {holders} holders", result, as_json)


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
@per_run("--lookups", 1000, "Timed lookups per ring, each from a random node.")
@click.option(
    "--seed", default=0, show_default=True, help="Seeds node ids, joins and keys (hops repeat)."
)
@plot_option("hops and latency against N")
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
    from mapbench.lookup import SWEEP, environment, measure_lookups

    sizes = sorted({*peers, *SWEEP}) if sweep else list(dict.fromkeys(peers or (32,)))
    machine = environment()  # before the runs, whose own load would count otherwise
    results = []
    for size in sizes:
        result = measure_lookups(size, lookups, seed=seed)
        measures(f"bench lookup: {size} peers", result, as_json)
        results.append(result)
    if plot:
        from mapbench.plot import plot_lookup

        plot_lookup(results, plot, machine)


@bench.command("spatial")
@repeatable(
    "--dataset",
    "datasets",
    click.Choice(["parking-garage", "tunnels"]),
    "Real missions to index (repeat for several; default both, unless --graph is given).",
)
@repeatable(
    "--graph",
    "graphs",
    click.Path(exists=True, dir_okay=False),
    "A .g2o file whose missions make a data set of their own (repeat).",
)
@repeatable(
    "--cells", "cells", click.IntRange(1), "Grid cells, n x n (repeat; default 1, 4, ..., 4096)."
)
@repeatable(
    "--latency",
    "latencies",
    click.FloatRange(0),
    "Added one-way link latency in ms (repeat; default 0, 5, 20).",
)
@click.option(
    "--peers", "-p", default=16, show_default=True, type=click.IntRange(1, 256), help="Chord nodes."
)
@per_run("--queries", 20, "Query boxes per row, each asked from a random node.")
@click.option(
    "--fraction",
    default=0.1,
    show_default=True,
    type=click.FloatRange(0, 1, min_open=True),
    help="A query box's side as a fraction of the map's horizontal extent "
    "(with --around-poses: the share of the poses a box holds).",
)
@click.option(
    "--around-poses",
    is_flag=True,
    help="Boxes around random poses, each holding --fraction of the poses.",
)
@click.option(
    "--seed", default=0, show_default=True, help="Seeds node ids, holders, boxes and askers."
)
@SAMPLES_OPTION
@plot_option("time, requests and entries against cells")
@json_option
def bench_spatial(
    datasets: tuple[str, ...],
    graphs: tuple[str, ...],
    cells: tuple[int, ...],
    latencies: tuple[float, ...],
    peers: int,
    queries: int,
    fraction: float,
    around_poses: bool,
    seed: int,
    samples: Path | None,
    plot: str | None,
    as_json: bool,
) -> None:
    """Spatial-index query cost against grid cells (Map API paper, Fig. 8).

    Real missions (parking-garage segments, tunnels robots, or a g2o file's)
    are registered on a ring of N nodes in this process, each by its box and by
    the boxes of its spatial tiles; random boxes are then queried with the
    exact filter at each cell's owner and without it. Both modes must find the
    same chunks, or the command fails (exit 1). Each row also says what a
    `query-bbox --load` of the findings moves (rows, bytes), against loading
    the whole missions. With --json, one object per (dataset, cells, latency),
    one per line.
    """
    from mapbench import spatial
    from mapbench.lookup import environment

    machine = environment()  # before the runs, whose own load would count otherwise
    rows = []
    for dataset in (*(datasets or ([] if graphs else spatial.DATASETS)), *graphs):
        for row in spatial.measure_spatial(
            dataset,
            cells=cells or spatial.CELLS,
            latencies_ms=latencies or spatial.LATENCIES_MS,
            peers=peers,
            queries=queries,
            seed=seed,
            fraction=fraction,
            samples=samples or spatial.SAMPLES,
            around_poses=around_poses,
        ):
            title = (
                f"bench spatial: {row['dataset']}, {row['cells']} cells, {row['latency_ms']:g} ms"
            )
            measures(title, row, as_json)
            rows.append(row)
    spatial.check_spatial(rows)
    if plot:
        from mapbench.plot import plot_spatial

        plot_spatial(rows, plot, machine)


@bench.command("triggers")
@repeatable(
    "--fraction",
    "fractions",
    click.FloatRange(0, 1),
    "Share of each writer's commits inside the region (repeat; default 0.05, 0.1, 0.25, 0.5).",
)
@repeatable(
    "--mode",
    "modes",
    click.Choice(["triggers", "polling", "replication", "idle"]),
    "How the subscribers follow the region (repeat; default all four).",
)
@click.option(
    "--writers", "-w", default=2, show_default=True, type=click.IntRange(1, 16), help="Writers."
)
@click.option(
    "--subscribers",
    "-s",
    default=2,
    show_default=True,
    type=click.IntRange(1, 16),
    help="Subscribers to the region.",
)
@click.option(
    "--peers",
    "-p",
    default=8,
    show_default=True,
    type=click.IntRange(2, 64),
    help="Peers on the ring (writers, subscribers, and peers that only serve the ring).",
)
@click.option(
    "--items", default=100, show_default=True, type=click.IntRange(3), help="Items per chunk."
)
@per_run("--commits", 20, "Commits per writer, one per round.")
@click.option("--seed", default=0, show_default=True, help="Seeds the peers' ids and the workload.")
@plot_option("bytes per subscriber against the share of commits inside the region")
@json_option
def bench_triggers(
    fractions: tuple[float, ...],
    modes: tuple[str, ...],
    writers: int,
    subscribers: int,
    peers: int,
    items: int,
    commits: int,
    seed: int,
    plot: str | None,
    as_json: bool,
) -> None:
    """Bytes a subscriber receives to follow a region (Map API paper, Fig. 6).

    Writers commit small updates inside and outside a 20 m x 20 m region of a
    200 m x 200 m map while subscribers follow it with triggers (pushes),
    polling (a spatial query and a fetch after every round of commits) or
    replication (holding the chunks); idle subscribers measure what a peer
    receives only for serving the ring. After every round each subscriber
    must know exactly the commits inside the region, or the command fails
    (exit 1). With --json, one object per (fraction, mode), one per line.
    """
    from mapbench import triggers
    from mapbench.lookup import environment

    machine = environment()  # before the runs, whose own load would count otherwise
    rows = triggers.measure_triggers(
        fractions=fractions or triggers.FRACTIONS,
        modes=modes or triggers.MODES,
        writers=writers,
        subscribers=subscribers,
        peers=peers,
        items=items,
        commits=commits,
        seed=seed,
    )
    for row in rows:
        title = f"bench triggers: {row['mode']}, {row['inside_fraction']:g} inside the region"
        measures(title, row, as_json)
    triggers.check_triggers(rows)
    if plot:
        from mapbench.plot_triggers import plot_triggers

        plot_triggers(rows, plot, machine)


@bench.command("plot")
@click.argument("kind", type=click.Choice(["viewtest", "commit", "scale"]))
@click.argument("results", nargs=-1, required=True, type=click.Path(dir_okay=False, exists=True))
@click.option(
    "-o", "--output", required=True, type=click.Path(dir_okay=False), help="The PNG to write."
)
def bench_plot(kind: str, results: tuple[str, ...], output: str) -> None:
    """Plot JSON results (one `--json` object per line in RESULTS) as a PNG.

    viewtest: commits/s and aborts per commit against peers; commit: p50/p99
    latency and messages per commit against holders; scale: seconds of each
    read against missions held, one line per result (`bench scale --label`
    names them). Needs matplotlib (the `dev` extra).
    """
    from mapbench.plot import load_results, plot_commit, plot_viewtest

    rows = load_results(results)
    if kind == "scale":
        from mapbench.plot_scale import plot_scale

        plot_scale(rows, output)
        return
    (plot_viewtest if kind == "viewtest" else plot_commit)(rows, output)


for _command in (*bench_faults.COMMANDS, *bench_maps.COMMANDS, *bench_mapping.COMMANDS):
    bench.add_command(_command)


def register(cli: click.Group) -> None:
    """Add this module's commands to `cli`."""
    cli.add_command(bench)
