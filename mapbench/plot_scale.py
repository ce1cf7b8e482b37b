"""The PNG of `mapctl bench scale --plot`: seconds of each read command of one
mission against the number of missions the repository holds (flat is the goal),
and the store's size per mission beside it."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from mapbench.plot import _hline, _pyplot, _save
from mapbench.scale import READS, TARGETS

_LABELS = {
    "missions": "missions",
    "export": "export (one mission, g2o)",
    "plot": "plot (one mission)",
    "query_bbox_load": "query-bbox --load (one mission's box)",
    "ls": "ls (one mission's vertices chunk)",
}
_MARKERS = {"missions": "o", "export": "s", "plot": "^", "query_bbox_load": "D", "ls": "v"}


def plot_scale(results: Sequence[dict[str, Any]], output: str | Path) -> None:
    """Median seconds per read against missions held (log-log), one line per
    read and per result given (a result's graph and label name it), with the
    issue's targets dotted; and the store's megabytes per mission held.

    Args:
        results: `bench scale --json` objects (a "label" key, when present,
            names a run in the legend, such as "before" and "after").
        output: the PNG to write.
    """
    plt = _pyplot()
    fig, (reads, size) = plt.subplots(
        1, 2, figsize=(13, 5), dpi=120, gridspec_kw={"width_ratios": (3, 1.3)}
    )
    styles = ("-", "--", ":", "-.")
    for n, result in enumerate(results):
        counts = [p["missions"] for p in result["points"]]
        for k, read in enumerate(READS):
            seconds = [p["seconds"][read] for p in result["points"]]
            style = styles[n % len(styles)]
            reads.plot(counts, seconds, marker=_MARKERS[read], ls=style, color=f"C{k}")
        per_mission = [p["store_bytes"] / 1e6 / p["missions"] for p in result["points"]]
        size.plot(counts, per_mission, marker="o", ls=styles[n % len(styles)], label=_tag(result))
    _legends(reads, results, styles)
    for read, target in TARGETS.items():
        text = f"target: {read} <= {target:g} s (10 missions)"
        _hline(reads, target, text, color="grey", ls=":")
    ticks = sorted({p["missions"] for r in results for p in r["points"]})
    for ax in (reads, size):
        _log_x(ax, ticks)
    reads.set_yscale("log")
    reads.set_xlabel("missions held (copies of one graph)")
    reads.set_ylabel("seconds (median of runs)")
    reads.grid(alpha=0.3, which="both")
    first = results[0]
    reads.set_title(
        f"Read cost against missions held: {first['graph']} "
        f"({first['vertices']:,} poses, {first['edges']:,} edges per mission)",
        fontsize=10,
    )
    size.set_ylim(bottom=0)
    size.set_xlabel("missions held")
    size.set_ylabel("store MB per mission (SQLite + WAL)")
    size.grid(alpha=0.3, which="both")
    size.legend(fontsize=7)
    _save(fig, list(results), output)
    plt.close(fig)


def _tag(result: dict[str, Any]) -> str:
    return str(result.get("label") or result["graph"])


def _legends(ax: Any, results: Sequence[dict[str, Any]], styles: Sequence[str]) -> None:
    """One legend of the reads (colour, marker), one of the runs (line style)."""
    from matplotlib.lines import Line2D

    reads = [
        Line2D([], [], color=f"C{k}", marker=_MARKERS[r], label=_LABELS[r])
        for k, r in enumerate(READS)
    ]
    runs = [
        Line2D([], [], color="black", ls=styles[n % len(styles)], label=_tag(result))
        for n, result in enumerate(results)
    ]
    first = ax.legend(handles=reads, fontsize=7, loc="upper left", framealpha=0.9)
    ax.add_artist(first)
    ax.legend(handles=runs, fontsize=7, loc="lower right", framealpha=0.9)


def _log_x(ax: Any, ticks: list[int]) -> None:
    """A log x axis ticked at the measured counts, labelled with them."""
    from matplotlib.ticker import NullFormatter, ScalarFormatter

    ax.set_xscale("log")
    ax.set_xticks(ticks)
    ax.xaxis.set_major_formatter(ScalarFormatter())
    ax.xaxis.set_minor_formatter(NullFormatter())
