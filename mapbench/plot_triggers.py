"""The PNG of `mapctl bench triggers --plot` (paper Fig. 6): bytes a subscriber
receives against the share of commits inside its region, per way of following
it, and the bytes cumulated over the run."""

from __future__ import annotations

import statistics
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from mapbench.plot import _by, _frame, _pyplot, _save, _series

_MODE_STYLES = {
    "triggers": {"color": "tab:green", "marker": "o", "label": "triggers (pushes)"},
    "polling": {"color": "tab:red", "marker": "s", "label": "polling (query + fetch per round)"},
    "replication": {"color": "tab:blue", "marker": "^", "label": "replication (holds the chunks)"},
    "idle": {"color": "grey", "marker": "x", "ls": "--", "label": "idle: serving the ring only"},
}


def plot_triggers(
    rows: Sequence[dict[str, Any]],
    output: str | Path,
    environment: dict[str, Any] | None = None,
) -> None:
    """Bytes a subscriber receives to follow a region, as the Map API paper's
    Fig. 6 (`mapctl bench triggers --plot`): per mode against the share of
    commits inside the region, with the target (1/5 of polling), and
    cumulated over the commits of the run nearest 10 % inside; both log y.

    Args:
        rows: `bench triggers --json` objects; several runs of one point are all drawn.
        output: the PNG to write.
        environment: the caption's machine, Python and load when `rows` lack
            them (`mapbench.lookup.environment()`, taken before the runs).
    """
    plt = _pyplot()
    rows = [
        {**(environment or {}), **row, "permille": round(1000 * row["inside_fraction"])}
        for row in rows
    ]
    fig, (share, growth) = plt.subplots(1, 2, figsize=(13, 4.8), dpi=120)
    _by_share(share, rows)
    _cumulated(growth, rows)
    for ax in (share, growth):
        ax.set_yscale("log")
        ax.autoscale(axis="y")
    bottom, top = share.get_ylim()
    share.set_ylim(bottom, 100 * top)  # two decades of headroom: the legend sits above the data
    share.legend(loc="upper center", ncol=2, fontsize=7, framealpha=0.9)
    growth.legend(loc="lower right", fontsize=7, framealpha=0.9)
    fig.suptitle("Triggers against polling (mapctl bench triggers), cf. paper Fig. 6", fontsize=11)
    _save(fig, rows, output)
    plt.close(fig)


def _by_share(ax: Any, rows: Sequence[dict[str, Any]]) -> None:
    """Bytes per subscriber against the share of commits inside the region (in
    per mille, labelled in %), per mode, with the target line and each
    triggers point's share of polling."""
    from matplotlib.ticker import FuncFormatter

    from mapbench.triggers import TARGET_RATIO

    for mode, style in _MODE_STYLES.items():
        mine = [r for r in rows if r["mode"] == mode]
        if mine:
            _series(ax, _by(mine, "permille", "bytes"), **style)
    polling = _by([r for r in rows if r["mode"] == "polling"], "permille", "bytes")
    if polling:
        targets = [TARGET_RATIO * statistics.median(v) for v in polling.values()]
        ax.plot(
            list(polling), targets, color="tab:red", ls=":", lw=1, label="target: 1/5 of polling"
        )
    for row in rows:
        if row["mode"] == "triggers" and row.get("ratio_to_polling") is not None:
            ax.annotate(
                f"{100 * row['ratio_to_polling']:.2g} % of polling",
                (row["permille"], row["bytes"]),
                xytext=(4, 5),  # above: the idle baseline runs just below
                textcoords="offset points",
                fontsize=7,
                color="tab:green",
            )
    _frame(
        ax,
        "commits inside the region (share of each writer's commits)",
        "bytes received per subscriber",
        rows,
        "permille",
    )
    ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v / 10:g} %"))
    ax.set_title("bytes per subscriber over the whole run", fontsize=10)


def _cumulated(ax: Any, rows: Sequence[dict[str, Any]]) -> None:
    """Bytes received so far against commits so far, per mode, in the runs whose
    share inside the region is nearest 10 %."""
    nearest = min({r["inside_fraction"] for r in rows}, key=lambda f: abs(f - 0.1))
    for row in rows:
        style = _MODE_STYLES.get(row["mode"])
        if row["inside_fraction"] != nearest or style is None:
            continue
        per_round = row["writers"]  # one commit per writer and round
        commits = [per_round * (k + 1) for k in range(len(row["bytes_by_round"]))]
        ax.plot(commits, row["bytes_by_round"], markersize=3, **style)
    ax.set_xlabel(f"commits so far (all writers; {100 * nearest:g} % of them inside the region)")
    ax.xaxis.get_major_locator().set_params(integer=True)
    ax.set_ylabel("bytes received so far, per subscriber")
    ax.grid(alpha=0.3)
    ax.set_title("bytes as the run goes on", fontsize=10)
