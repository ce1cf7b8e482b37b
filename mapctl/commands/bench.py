"""`bench ...`: measurements (never assertions)."""

from __future__ import annotations

from pathlib import Path
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
    from mapbench.local import run_local
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
_SECURE_OPTION = click.option(
    "--secure", is_flag=True, help="A secure swarm: CurveZMQ between peers that trust each other."
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
@_SECURE_OPTION
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
@_SECURE_OPTION
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
        writer="arbiter" if writer == "arbiter" else "other",
        directory=directory,
        use_uvloop=use_uvloop,
        secure=secure,
    )
    _render(f"bench commit: {holders} holders", result, as_json)


def _repeatable(flag: str, dest: str, kind: click.ParamType, text: str) -> Any:
    """An option that may be given several times (`dest` collects a tuple)."""
    return click.option(flag, flag[1:3], dest, multiple=True, type=kind, help=text)


def _plot_option(what: str) -> Any:
    """`--plot FILE`: also write a PNG of `what`."""
    return click.option(
        "--plot", type=click.Path(dir_okay=False), help=f"Also write a PNG of {what} (matplotlib)."
    )


def _per_run(flag: str, default: int, text: str) -> Any:
    """`-n`: how many timed operations a run makes."""
    return click.option(
        flag, "-n", default=default, show_default=True, type=click.IntRange(1), help=text
    )


_SAMPLES_OPTION = click.option(
    "--samples",
    type=click.Path(file_okay=False, exists=True, path_type=Path),
    help="The sample_maps folder (default: the one of this source tree).",
)


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
@_per_run("--lookups", 1000, "Timed lookups per ring, each from a random node.")
@click.option(
    "--seed", default=0, show_default=True, help="Seeds node ids, joins and keys (hops repeat)."
)
@_plot_option("hops and latency against N")
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
        _render(f"bench lookup: {size} peers", result, as_json)
        results.append(result)
    if plot:
        from mapbench.plot import plot_lookup

        plot_lookup(results, plot, machine)


@bench.command("spatial")
@_repeatable(
    "--dataset",
    "datasets",
    click.Choice(["parking-garage", "tunnels"]),
    "Real missions to index (repeat for several; default both).",
)
@_repeatable(
    "--cells", "cells", click.IntRange(1), "Grid cells, n x n (repeat; default 1, 4, ..., 4096)."
)
@_repeatable(
    "--latency",
    "latencies",
    click.FloatRange(0),
    "Added one-way link latency in ms (repeat; default 0, 5, 20).",
)
@click.option(
    "--peers", "-p", default=16, show_default=True, type=click.IntRange(1, 256), help="Chord nodes."
)
@_per_run("--queries", 20, "Query boxes per row, each asked from a random node.")
@click.option(
    "--fraction",
    default=0.1,
    show_default=True,
    type=click.FloatRange(0, 1, min_open=True),
    help="A query box's side as a fraction of the map's horizontal extent.",
)
@click.option(
    "--seed", default=0, show_default=True, help="Seeds node ids, holders, boxes and askers."
)
@_SAMPLES_OPTION
@_plot_option("time, requests and entries against cells")
@json_option
def bench_spatial(
    datasets: tuple[str, ...],
    cells: tuple[int, ...],
    latencies: tuple[float, ...],
    peers: int,
    queries: int,
    fraction: float,
    seed: int,
    samples: Path | None,
    plot: str | None,
    as_json: bool,
) -> None:
    """Spatial-index query cost against grid cells (Map API paper, Fig. 8).

    Real missions (parking-garage segments, tunnels robots) are registered on
    a ring of N nodes in this process; random boxes are then queried with the
    exact filter at each cell's owner and without it. Both modes must find the
    same missions, or the command fails (exit 1). With --json, one object per
    (dataset, cells, latency), one per line.
    """
    from mapbench import spatial
    from mapbench.lookup import environment

    machine = environment()  # before the runs, whose own load would count otherwise
    rows = []
    for dataset in datasets or spatial.DATASETS:
        for row in spatial.measure_spatial(
            dataset,
            cells=cells or spatial.CELLS,
            latencies_ms=latencies or spatial.LATENCIES_MS,
            peers=peers,
            queries=queries,
            seed=seed,
            fraction=fraction,
            samples=samples or spatial.SAMPLES,
        ):
            title = f"bench spatial: {dataset}, {row['cells']} cells, {row['latency_ms']:g} ms"
            _render(title, row, as_json)
            rows.append(row)
    spatial.check_spatial(rows)
    if plot:
        from mapbench.plot import plot_spatial

        plot_spatial(rows, plot, machine)


def _bandwidth(flag: str, default: float, when: str) -> Any:
    """A link bandwidth in kB/s (1 kB = 1000 bytes)."""
    kind = click.FloatRange(0, min_open=True)
    text = f"kB/s of every link when {when}."
    return click.option(flag, default=default, show_default=True, type=kind, help=text)


@bench.command("registration")
@click.option(
    "--ground", type=click.IntRange(1, 7), help="Ground robots: robots 0..N-1 (default 4)."
)
@click.option(
    "--aerial", type=click.IntRange(1, 7), help="Aerial robots: the last N robots (default 4)."
)
@click.option(
    "--vertices",
    type=click.IntRange(2),
    help="Cut every mission to its first N vertices (default: keep all).",
)
@click.option(
    "--quick",
    is_flag=True,
    help="2 ground and 2 aerial missions of 50 vertices: seconds (the options above override).",
)
@_bandwidth("--decentralized-bandwidth", 1000.0, "each ground peer registers what is near it")
@_bandwidth("--centralized-bandwidth", 100.0, "one server fetches and registers everything")
@click.option("--seed", default=0, show_default=True, help="Seeds the peers' ids.")
@_SAMPLES_OPTION
@_plot_option("transfer and compute time per peer, and the residuals")
@json_option
def bench_registration(
    ground: int | None,
    aerial: int | None,
    vertices: int | None,
    quick: bool,
    decentralized_bandwidth: float,
    centralized_bandwidth: float,
    seed: int,
    samples: Path | None,
    plot: str | None,
    as_json: bool,
) -> None:
    """Register aerial missions against ground missions (Map API paper, Fig. 7).

    The tunnels set's robots are split into ground robots and "aerial" ones
    (it has no aerial robot). Decentralized, each ground peer fetches the
    aerial missions its own inter-robot edges reach and registers them
    against its mission (gtsam); centralized, one server fetches every
    mission over slower links and runs every registration. Reports bytes,
    transfer and compute seconds per peer; both modes must find the same
    frames, or the command fails (exit 1). Needs gtsam (`pip install
    'mapapi[registration]'`). With --json, one object.
    """
    from mapbench import registration

    sizes = registration.QUICK if quick else {}
    layout = registration.plan(
        ground if ground is not None else sizes.get("ground", registration.DEFAULT_GROUND),
        aerial if aerial is not None else sizes.get("aerial", registration.DEFAULT_AERIAL),
        vertices if vertices is not None else sizes.get("vertices"),
        samples or registration.SAMPLES,
    )
    result = registration.measure_registration(
        layout,
        bandwidths={
            "decentralized": decentralized_bandwidth * 1e3,
            "centralized": centralized_bandwidth * 1e3,
        },
        seed=seed,
    )
    _render_registration(result, as_json)
    registration.check_registration(result)
    if plot:
        from mapbench.plot_registration import plot_registration

        plot_registration(result, plot)


def _render_registration(result: dict[str, Any], as_json: bool) -> None:
    from mapctl import render

    if as_json:
        render.emit_json(result)
        return
    for run in result["runs"]:
        render.table(
            f"bench registration: {run['mode']}, {run['bandwidth'] / 1e3:g} kB/s links, "
            f"wall {run['wall_s']:.2f} s",
            ["peer", "fetched", "MB", "transfer s", "compute s", "total s"],
            [
                (
                    p["peer"],
                    ", ".join(p["missions"]) or "-",
                    f"{p['bytes'] / 1e6:.3f}",
                    p["transfer_s"],
                    p["compute_s"],
                    p["total_s"],
                )
                for p in run["peers"]
            ],
        )
    render.table(
        "registrations (RMS residual of the kept inter-mission edges)",
        ["mode", "reference", "registered", "kept edges", "before m / deg", "after m / deg"],
        [
            (
                run["mode"],
                r["reference"],
                ", ".join(r["missions"]),
                f"{r['inliers']} of {r['edges']}",
                f"{r['rms_m_before']:.3g} / {r['rms_deg_before']:.3g}",
                f"{r['rms_m_after']:.3g} / {r['rms_deg_after']:.3g}",
            )
            for run in result["runs"]
            for r in run["registrations"]
        ],
    )
    if result["frame_difference_m"] is not None:
        render.line(
            f"frames differ between the modes by at most {result['frame_difference_m']:.2g} m "
            f"and {result['frame_difference_deg']:.2g} deg"
        )


@bench.command("import")
@_repeatable(
    "--dataset",
    "datasets",
    click.Choice(["intel", "parking-garage", "tunnels"]),
    "Sample graph to import (repeat for several; default all three).",
)
@click.option(
    "--store",
    type=click.Choice(["sqlite", "memory"]),
    default="sqlite",
    show_default=True,
    help="A fresh repository on disk, or the in-memory store (leaves SQLite out).",
)
@_per_run("--runs", 3, "Imports per data set, each into a fresh repository (the median counts).")
@_DIR_OPTION
@json_option
def bench_import(
    datasets: tuple[str, ...], store: str, runs: int, directory: str | None, as_json: bool
) -> None:
    """Graph elements (vertices + edges) imported per second (issue 5 target:
    50,000), for the parse alone, parse + staging, and end to end with the commit.

    With --json, one object per data set, one per line.
    """
    from mapbench.maps import DATASETS, measure_import

    for dataset in datasets or DATASETS:
        result = measure_import(dataset, runs=runs, store=store, directory=directory)
        _render(f"bench import: {dataset} ({store})", result, as_json)


@bench.command("triggers")
@_repeatable(
    "--fraction",
    "fractions",
    click.FloatRange(0, 1),
    "Share of each writer's commits inside the region (repeat; default 0.05, 0.1, 0.25, 0.5).",
)
@_repeatable(
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
@_per_run("--commits", 20, "Commits per writer, one per round.")
@click.option("--seed", default=0, show_default=True, help="Seeds the peers' ids and the workload.")
@_plot_option("bytes per subscriber against the share of commits inside the region")
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
        _render(title, row, as_json)
    triggers.check_triggers(rows)
    if plot:
        from mapbench.plot import plot_triggers

        plot_triggers(rows, plot, machine)


@bench.command("fuzz")
@click.option(
    "--messages",
    "-n",
    "messages_n",
    default=10_000,
    show_default=True,
    type=click.IntRange(1),
    help="Hostile messages to send.",
)
@click.option("--seed", default=0, show_default=True, help="Seeds the generator (a run replays).")
@_DIR_OPTION
@json_option
def bench_fuzz(messages_n: int, seed: int, directory: str | None, as_json: bool) -> None:
    """Send N hostile messages to a real peer and check it survives (DESIGN §11).

    Three peer processes hold chunks with history; generated and mutated
    messages of every body type (valid, with hostile fields, or broken bytes)
    go to one of them as strangers and as a member. Every request must get an
    error reply or a valid reply (or be counted as dropped when its request id
    cannot be read); afterwards the peer must answer a Ping and a commit
    through it, and its store must be intact and changed only by acknowledged
    commits. Fails (exit 1) otherwise.
    """
    from mapbench.fuzz import check_fuzz, run_fuzz

    report = run_fuzz(messages_n, seed, directory)
    _render(f"bench fuzz: {messages_n} messages, seed {seed}", report, as_json)
    check_fuzz(report)


@bench.command("flood")
@click.option(
    "--senders", "-n", default=20, show_default=True, type=click.IntRange(1, 200),
    help="Sender processes.",
)  # fmt: skip
@click.option(
    "--megabytes", "-m", default=120, show_default=True, type=click.IntRange(1, 4096),
    help="MB each sender sends.",
)  # fmt: skip
@click.option(
    "--mode", type=click.Choice(["frame", "parts", "both"]), default="both", show_default=True,
    help="One frame per sender (the probe), or parts as a mapapi peer sends a large message.",
)  # fmt: skip
@json_option
def bench_flood(senders: int, megabytes: int, mode: str, as_json: bool) -> None:
    """Flood a real peer process with large messages from N sender processes and
    report the peak of its resident memory and its ping latency (issue 18 §5)."""
    from mapbench.flood import MODES, asdict, run_flood

    modes = MODES if mode == "both" else (mode,)
    for each in modes:
        report = asdict(run_flood(senders, megabytes, each))
        _render(f"bench flood: {senders} x {megabytes} MB, {each}", report, as_json)


@bench.command("soak")
@click.option(
    "--minutes",
    default=10.0,
    show_default=True,
    type=click.FloatRange(0.1),
    help="How long the peers commit while the chaos runs.",
)
@click.option(
    "--peers", "-p", default=4, show_default=True, type=click.IntRange(3, 16), help="Processes."
)
@click.option("--seed", default=0, show_default=True, help="Seeds the workload and the chaos.")
@_DIR_OPTION
@json_option
def bench_soak(minutes: float, peers: int, seed: int, directory: str | None, as_json: bool) -> None:
    """Peer daemons commit increments and bank transfers while they crash
    (kill -9), leave and come back at random; then check that no acknowledged
    commit was lost, the bank total held and every history agrees (issue 7).

    Exits 1 if an invariant broke. Progress goes to stderr after each crash,
    stop or restart.
    """
    import asyncio
    import shutil
    import tempfile

    from mapbench.soak import measure_soak
    from mapctl import render

    def progress(tally: dict[str, Any]) -> None:
        render.note(
            f"soak: {tally['increments']} increments, {tally['transfers']} transfers, "
            f"{tally['crashes']} crashes, {tally['stops']} stops, {tally['restarts']} restarts"
        )

    root = Path(tempfile.mkdtemp(prefix="mapapi-soak-", dir=directory))
    try:
        result = asyncio.run(measure_soak(root, peers, minutes * 60, seed, progress))
    except BaseException:
        render.note(f"soak: the peers' repositories and logs are kept in {root}")
        raise
    _render("bench soak", result, as_json)
    if not result["invariants_ok"] or result["errors"]:
        render.note(f"soak: the peers' repositories and logs are kept in {root}")
    else:
        shutil.rmtree(root, ignore_errors=True)
    if not result["invariants_ok"]:
        raise SystemExit(1)


@bench.command("sim")
@click.option(
    "--seeds", "-n", default=100, show_default=True, type=click.IntRange(1), help="Seeds to run."
)
@click.option("--first", default=0, show_default=True, type=click.IntRange(0), help="First seed.")
@click.option(
    "--mode",
    type=click.Choice(["core", "commits", "both"]),
    default="both",
    show_default=True,
    help="The pure Raft core's counter, the commit path on stores, or both.",
)
@json_option
def bench_sim(seeds: int, first: int, mode: str, as_json: bool) -> None:
    """Deterministic simulation of a chunk's Raft group under faults (DESIGN §13):
    seeds FIRST .. FIRST+SEEDS-1, each in one thread with a simulated network and clock.

    Reports violations (each with the command that replays its seed) and what
    the runs did. Exits 1 if any seed broke an invariant.
    """
    from mapbench.sim import run_seeds
    from mapctl import render

    modes = ("core", "commits") if mode == "both" else (mode,)
    result = run_seeds(first, seeds, modes)
    if as_json:
        render.emit_json(result)
    else:
        flat = {f"{m} {k}": v for m in modes for k, v in result[m].items()}
        rows = {k: v for k, v in result.items() if k not in modes and k != "violations"}
        _render(f"bench sim: seeds {first}..{first + seeds - 1}", {**rows, **flat}, False)
        for bad in result["violations"]:
            render.note(f"{bad['mode']} seed {bad['seed']}: {bad['error']}\n  {bad['replay']}")
    if result["violations"]:
        raise SystemExit(1)


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
    from mapbench.plot import load_results, plot_commit, plot_viewtest

    rows = load_results(results)
    (plot_viewtest if kind == "viewtest" else plot_commit)(rows, output)


def register(cli: click.Group) -> None:
    """Add this module's commands to `cli`."""
    cli.add_command(bench)
