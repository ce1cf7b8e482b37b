"""`bench registration|import`: the map layer's benchmarks (paper Fig. 7, and
import throughput on real pose graphs)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import click

from mapctl.commands.bench_options import (
    DIR_OPTION,
    SAMPLES_OPTION,
    measures,
    per_run,
    plot_option,
    repeatable,
)
from mapctl.session import json_option


def _bandwidth(flag: str, default: float, when: str) -> Any:
    """A link bandwidth in kB/s (1 kB = 1000 bytes)."""
    kind = click.FloatRange(0, min_open=True)
    text = f"kB/s of every link when {when}."
    return click.option(flag, default=default, show_default=True, type=kind, help=text)


@click.command("registration")
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
@SAMPLES_OPTION
@plot_option("transfer and compute time per peer, and the residuals")
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


@click.command("import")
@repeatable(
    "--dataset",
    "datasets",
    click.Choice(["intel", "parking-garage", "tunnels", "victoria-park", "dgs-blocks"]),
    "Sample graph to import (repeat for several; default all).",
)
@click.option(
    "--store",
    type=click.Choice(["sqlite", "memory"]),
    default="sqlite",
    show_default=True,
    help="A fresh repository on disk, or the in-memory store (leaves SQLite out).",
)
@click.option(
    "--file",
    "path",
    type=click.Path(exists=True, path_type=Path),
    help="Measure this map file instead (any format `mapctl import` reads; e.g. a CARMEN log).",
)
@per_run("--runs", 3, "Imports per data set, each into a fresh repository (the median counts).")
@DIR_OPTION
@json_option
def bench_import(
    datasets: tuple[str, ...],
    store: str,
    path: Path | None,
    runs: int,
    directory: str | None,
    as_json: bool,
) -> None:
    """Graph elements (vertices, landmarks and edges) imported per second (issue 5 target:
    50,000), for the parse alone, parse + staging, and end to end with the commit.

    With --json, one object per data set, one per line.
    """
    from mapbench.maps import DATASETS, measure_import

    if path is not None:
        if datasets:
            raise click.UsageError("--file and --dataset measure different maps; pass one")
        result = measure_import(path.name, runs=runs, store=store, directory=directory, path=path)
        measures(f"bench import: {path.name} ({store})", result, as_json)
        return
    for dataset in datasets or DATASETS:
        result = measure_import(dataset, runs=runs, store=store, directory=directory)
        measures(f"bench import: {dataset} ({store})", result, as_json)


@click.command("scale")
@click.option(
    "--missions",
    "counts",
    default="1,10",
    show_default=True,
    help="Missions held when the reads are timed, comma-separated (the issue's: 1,10,100).",
)
@click.option(
    "--graph",
    type=click.Path(dir_okay=False, exists=True, path_type=Path),
    help="The g2o pose graph copied as every mission (default: the intel sample).",
)
@per_run("--runs", 3, "Timed runs of each read at each count (the median counts).")
@click.option("--label", default="", help="Name the run in plots (e.g. before, after).")
@DIR_OPTION
@plot_option("seconds of each read against missions held")
@json_option
def bench_scale(
    counts: str,
    graph: Path | None,
    runs: int,
    label: str,
    directory: str | None,
    plot: str | None,
    as_json: bool,
) -> None:
    """Seconds of each read command of one mission (missions, export, plot,
    query-bbox --load, ls) as one fresh repository grows to each count of
    missions, all copies of one real graph (issue 14: flat is the goal).

    With --json, one object.
    """
    from mapbench.scale import DEFAULT_GRAPH, READS, measure_scale, parse_counts
    from mapctl import render

    result = measure_scale(
        parse_counts(counts), graph or DEFAULT_GRAPH, runs=runs, directory=directory, label=label
    )
    if as_json:
        render.emit_json(result)
    else:
        render.table(
            f"bench scale: {result['graph']} ({result['vertices']:,} poses, "
            f"{result['edges']:,} edges per mission), median of {runs} run(s), seconds",
            ["missions", "store MB", *READS],
            [
                (p["missions"], f"{p['store_bytes'] / 1e6:.1f}", *(p["seconds"][r] for r in READS))
                for p in result["points"]
            ],
        )
    if plot:
        from mapbench.plot_scale import plot_scale

        plot_scale([result], plot)


COMMANDS = (bench_registration, bench_import, bench_scale)
"""The commands of this module, which the `bench` group adds."""
