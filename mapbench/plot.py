"""PNG plots of swarm benchmark results (`mapctl bench plot`), with matplotlib.

The input is what `mapctl bench viewtest --json` and `bench commit --json`
print, one object per line (a JSON-lines file); several runs of the same P or K
are drawn as points with their median joined by a line. matplotlib is a dev
dependency and is imported only here.
"""

from __future__ import annotations

import json
import math
import statistics
from collections import defaultdict
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

REDIS_4_CLIENTS = 1_700  # DESIGN §12: Redis 7 WATCH/MULTI, 4 clients, this machine
TARGET_P4 = 1_500  # issue 3: viewtest with 4 peers
TARGET_K3_P50_MS = 1.0  # issue 3: uncontended commit with 3 holders


def load_results(paths: Iterable[str | Path]) -> list[dict[str, Any]]:
    """Every JSON object in the given JSON-lines files (blank lines skipped)."""
    rows = []
    for path in paths:
        for line in Path(path).read_text().splitlines():
            if line.strip():
                rows.append(json.loads(line))
    return rows


def _by(rows: Sequence[dict[str, Any]], key: str, value: str) -> dict[int, list[float]]:
    out: dict[int, list[float]] = defaultdict(list)
    for row in rows:
        out[int(row[key])].append(float(row[value]))
    return dict(sorted(out.items()))


def _series(ax: Any, points: dict[int, list[float]], label: str, **style: Any) -> None:
    xs = [x for x, ys in points.items() for _ in ys]
    ys = [y for _, values in points.items() for y in values]
    line = ax.plot(
        list(points), [statistics.median(v) for v in points.values()], label=label, **style
    )
    ax.scatter(xs, ys, s=14, alpha=0.5, color=line[0].get_color())


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")  # files only, no display
    import matplotlib.pyplot as plt

    return plt


def _caption(rows: Sequence[dict[str, Any]]) -> str:
    first = rows[0]
    loads = [r.get("load_1min_before", 0.0) for r in rows]
    return (
        f"{first.get('machine', '?')}, Python {first.get('python', '?')}, "
        f"{first.get('loop', 'asyncio')}, loopback; load before runs <= {max(loads):.2f}"
    )


def _hline(ax: Any, y: float, text: str, **style: Any) -> None:
    """A horizontal reference line, labelled at the right end."""
    ax.axhline(y, lw=1, **style)
    ax.annotate(
        text,
        (1.0, y),
        xycoords=("axes fraction", "data"),
        xytext=(-4, 3),
        textcoords="offset points",
        ha="right",
        fontsize=8,
        color=style.get("color", "black"),
    )


def _finish(
    fig: Any,
    ax: Any,
    twin: Any,
    rows: Sequence[dict[str, Any]],
    output: str | Path,
    legend: str = "upper left",
) -> None:
    """Legend of both axes, the caption, and the file."""
    handles = ax.get_legend_handles_labels()[0] + twin.get_legend_handles_labels()[0]
    labels = ax.get_legend_handles_labels()[1] + twin.get_legend_handles_labels()[1]
    ax.legend(handles, labels, loc=legend, fontsize=8, framealpha=0.9)
    _save(fig, rows, output)


def _save(fig: Any, rows: Sequence[dict[str, Any]], output: str | Path) -> None:
    """The caption under the panels, then the file."""
    fig.text(0.01, 0.01, _caption(rows), fontsize=7, color="dimgray")
    fig.tight_layout(rect=(0, 0.03, 1, 1))
    fig.savefig(output)


def plot_viewtest(rows: Sequence[dict[str, Any]], output: str | Path) -> None:
    """Commits/s (and aborts per commit) against the number of peers."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7, 4.2), dpi=120)
    throughput = _by(rows, "peers", "commits_per_s")
    _series(ax, throughput, "commits/s (line: median of runs)", marker="o")
    for peers, values in throughput.items():
        median = statistics.median(values)
        ax.annotate(
            f"{median:,.0f}/s",
            (peers, median),
            xytext=(6, 4),
            textcoords="offset points",
            fontsize=8,
            color="tab:blue",
        )
    _hline(ax, REDIS_4_CLIENTS, "central Redis WATCH/MULTI, 4 clients", color="grey", ls="--")
    _hline(ax, TARGET_P4, "target at P = 4", color="tab:red", ls=":")
    _frame(
        ax,
        "peer processes P (each commits N increments of one counter)",
        "commits / s",
        rows,
        "peers",
    )
    aborts = _right_axis(
        ax, _by(rows, "peers", "aborts_per_commit"), "aborts per commit", "tab:orange"
    )
    ax.set_title("Algorithm 1 (mapctl bench viewtest): throughput against peers", fontsize=10)
    _finish(fig, ax, aborts, rows, output, legend="upper center")
    plt.close(fig)


def _frame(ax: Any, xlabel: str, ylabel: str, rows: Sequence[dict[str, Any]], x: str) -> None:
    """Label the left axis, tick every measured x, start y at 0, draw a light grid."""
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_xticks(sorted({int(r[x]) for r in rows}))
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)


def _log2_x(ax: Any) -> None:
    """A log2 x axis labelled with the measured values themselves."""
    from matplotlib.ticker import NullFormatter, ScalarFormatter

    ax.set_xscale("log", base=2)
    ax.xaxis.set_major_formatter(ScalarFormatter())  # 8, 16, ... rather than 2^3, 2^4, ...
    ax.xaxis.set_minor_formatter(NullFormatter())


def _right_axis(ax: Any, points: Any, label: str, color: str) -> Any:
    """A second series on a right-hand axis of its own (dashed, square markers)."""
    right = ax.twinx()
    _series(right, points, f"{label} (right axis)", ls="--", marker="s", color=color)
    right.set_ylabel(label)
    right.set_ylim(bottom=0)
    return right


def plot_commit(rows: Sequence[dict[str, Any]], output: str | Path) -> None:
    """Uncontended commit latency (p50, p99) and messages per commit against holders."""
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7, 4.2), dpi=120)
    for writer, color in (("follower", "tab:blue"), ("leader", "tab:green")):
        mine = [r for r in rows if r.get("writer", "other") == writer or int(r["holders"]) == 1]
        if not any(r.get("writer") == writer for r in mine):
            continue
        who = "writer follows" if writer == "follower" else "writer leads"
        _series(ax, _by(mine, "holders", "p50_ms"), f"p50, {who}", marker="o", color=color)
        _series(
            ax,
            _by(mine, "holders", "p99_ms"),
            f"p99, {who}",
            marker="^",
            ls=":",
            lw=1,
            color=color,
            alpha=0.6,
        )
    _hline(ax, TARGET_K3_P50_MS, "target: p50 at K = 3", color="tab:red", ls=":")
    _frame(
        ax,
        "holders K (peer processes replicating the chunk, the writer included)",
        "commit latency, ms",
        rows,
        "holders",
    )
    messages = _right_axis(
        ax, _by(rows, "holders", "messages_per_commit"), "messages per commit, all peers", "grey"
    )
    ax.set_title("Uncontended commit (mapctl bench commit): latency against holders", fontsize=10)
    _finish(fig, ax, messages, rows, output)
    plt.close(fig)


def plot_lookup(
    rows: Sequence[dict[str, Any]],
    output: str | Path,
    environment: dict[str, Any] | None = None,
) -> None:
    """Chord lookup hops (mean, p99) and latency (p50, p99) against ring size N,
    with the target mean ½·log2 N + 1 (`mapctl bench lookup --plot`).

    Args:
        rows: `bench lookup --json` objects; several runs of one N are all drawn.
        output: the PNG to write.
        environment: the caption's machine, Python and load when `rows` lack
            them (`mapbench.lookup.environment()`, taken before the runs).
    """
    plt = _pyplot()
    rows = [{**(environment or {}), **row} for row in rows]
    fig, ax = plt.subplots(figsize=(7, 4.2), dpi=120)
    _series(ax, _by(rows, "peers", "mean_hops"), "mean hops", marker="o", color="tab:blue")
    _series(ax, _by(rows, "peers", "p99_hops"), "p99 hops", marker="^", ls=":", color="tab:blue")
    sizes = sorted({int(r["peers"]) for r in rows})
    targets = [0.5 * math.log2(n) + 1 for n in sizes]
    ax.plot(sizes, targets, color="tab:red", ls="--", lw=1, label="target mean: ½·log2 N + 1")
    _frame(
        ax, "Chord nodes N (log scale; all in one process and event loop)", "hops", rows, "peers"
    )
    _log2_x(ax)
    latency = _right_axis(ax, _by(rows, "peers", "p50_ms"), "p50 latency, ms", "grey")
    _series(
        latency,
        _by(rows, "peers", "p99_ms"),
        "p99 latency, ms (right axis)",
        marker="v",
        ls=":",
        lw=1,
        color="grey",
        alpha=0.6,
    )
    latency.set_ylabel("lookup latency, ms")
    latency.autoscale(axis="y")  # `_right_axis` froze the top before the p99 series
    for axis in (ax, latency):  # headroom: the legend sits above the data, not on it
        axis.set_ylim(0, 1.5 * axis.get_ylim()[1])
    ax.set_title("Chord lookups (mapctl bench lookup): hops and latency against N", fontsize=10)
    _finish(fig, ax, latency, rows, output)
    plt.close(fig)


_LATENCY_COLORS = ("tab:blue", "tab:orange", "tab:red", "tab:green", "tab:purple", "tab:brown")
_DATASET_STYLES = (
    {"ls": "-", "marker": "o"},
    {"ls": "--", "marker": "s"},
    {"ls": ":", "marker": "^"},
)


def plot_spatial(
    rows: Sequence[dict[str, Any]],
    output: str | Path,
    environment: dict[str, Any] | None = None,
) -> None:
    """Spatial-index query cost against grid cells, as the Map API paper's Fig. 8
    (`mapctl bench spatial --plot`): three log-log panels, query time per added
    latency, Chord requests per query, and entries returned per query with and
    without exact filtering at the cell owners (with the missions found).

    Args:
        rows: `bench spatial --json` objects; a line style per data set.
        output: the PNG to write.
        environment: the caption's machine, Python and load when `rows` lack
            them (`mapbench.lookup.environment()`, taken before the runs).
    """
    plt = _pyplot()
    rows = [{**(environment or {}), **row} for row in rows]
    datasets = list(dict.fromkeys(r["dataset"] for r in rows))
    latencies = sorted({float(r["latency_ms"]) for r in rows})
    fig, (times, requests, entries) = plt.subplots(1, 3, figsize=(15, 4.8), dpi=120)
    for dataset, style in zip(datasets, _DATASET_STYLES, strict=False):
        mine = [r for r in rows if r["dataset"] == dataset]
        for latency, color in zip(latencies, _LATENCY_COLORS, strict=False):
            at = [r for r in mine if float(r["latency_ms"]) == latency]
            label = f"{dataset}, +{latency:g} ms one-way link latency"
            _series(times, _by(at, "cells", "query_ms"), label, color=color, **style)
        # requests and entries do not depend on the latency: its rows' points coincide
        for ax, key, label, color in (
            (requests, "requests", "requests", "tab:blue"),
            (requests, "cells_asked", "cells asked", "grey"),
            (entries, "returned_all", "without filtering", "tab:red"),
            (entries, "returned_exact", "exact filtering at the owner", "tab:green"),
            (entries, "matches", "missions found", "black"),
        ):
            _series(ax, _by(mine, "cells", key), f"{dataset}: {label}", color=color, **style)
    cells = "grid cells (n x n, log scale)"
    for ax, ylabel, title in (
        (times, "query time, ms (exact filtering)", "query time"),
        (requests, "per query", "Chord requests sent by the asker, cells asked"),
        (entries, "entries per query", "entries travelling back from the asked cells"),
    ):
        _frame(ax, cells, ylabel, rows, "cells")
        _log2_x(ax)
        ax.set_yscale("log")
        ax.autoscale(axis="y")
        bottom, top = ax.get_ylim()
        ax.set_ylim(bottom, 10 * top)  # a decade of headroom: the legend sits above the data
        ax.set_title(title, fontsize=10)
        ax.legend(loc="upper left", fontsize=7, framealpha=0.9)
    fig.suptitle(
        "Spatial index (mapctl bench spatial): query cost against grid cells, cf. paper Fig. 8",
        fontsize=11,
    )
    _save(fig, rows, output)
    plt.close(fig)
