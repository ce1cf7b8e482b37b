"""The PNG of `mapctl bench registration --plot`, drawn like the Map API paper's
Fig. 7: per fetching peer, a bar of transfer time with its compute time stacked
on top, decentralized peers beside the centralized server; and beside it the
registration's residuals, before and after, per job and mode."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from mapbench.plot import _pyplot, _save

_MODE_COLORS = {"decentralized": "tab:green", "centralized": "tab:red"}


def plot_registration(result: dict[str, Any], output: str | Path) -> None:
    """Transfer and compute seconds per peer (stacked bars, each mode's wall
    time dashed), and the RMS residual of the kept inter-mission edges per job.

    Args:
        result: what `measure_registration` returns (`bench registration --json`).
        output: the PNG to write.
    """
    plt = _pyplot()
    fig, (times, quality) = plt.subplots(
        1, 2, figsize=(13, 4.8), dpi=120, gridspec_kw={"width_ratios": (3, 2)}
    )
    _times(times, result)
    _quality(quality, result)
    fig.suptitle(
        "Registering aerial missions against ground missions (mapctl bench registration), "
        "cf. paper Fig. 7",
        fontsize=11,
    )
    _save(fig, [result], output)
    plt.close(fig)


def _times(ax: Any, result: dict[str, Any]) -> None:
    labels, transfer, compute, colors = [], [], [], []
    for run in result["runs"]:
        for peer in run["peers"]:
            labels.append(
                f"{peer['peer']}\n{run['mode']}\n{run['bandwidth'] / 1e3:g} kB/s links\n"
                f"fetched {peer['bytes'] / 1e6:.2f} MB"
            )
            transfer.append(peer["transfer_s"])
            compute.append(peer["compute_s"])
            colors.append(_MODE_COLORS.get(run["mode"], "grey"))
    xs = range(len(labels))
    ax.bar(xs, transfer, color="tab:blue", label="transfer (fetching the missions)")
    ax.bar(xs, compute, bottom=transfer, color="tab:orange", label="compute (read + register)")
    for run in result["runs"]:
        color = _MODE_COLORS.get(run["mode"], "grey")
        ax.axhline(run["wall_s"], color=color, ls="--", lw=1)
        ax.annotate(
            f"{run['mode']}: {run['wall_s']:.1f} s",
            (0.0, run["wall_s"]),
            xycoords=("axes fraction", "data"),
            xytext=(4, 3),
            textcoords="offset points",
            fontsize=8,
            color=color,
        )
    ax.set_xticks(list(xs), labels, fontsize=7)
    for tick, color in zip(ax.get_xticklabels(), colors, strict=True):
        tick.set_color(color)
    ax.set_ylabel("seconds")
    ax.set_ylim(0, 1.2 * max((r["wall_s"] for r in result["runs"]), default=1.0))
    ax.grid(axis="y", alpha=0.3)
    ax.legend(loc="upper center", fontsize=8, framealpha=0.9)
    ax.set_title("time per fetching peer (dashed: the run's wall time)", fontsize=10)


def _quality(ax: Any, result: dict[str, Any]) -> None:
    runs = result["runs"]
    jobs = [row["reference"] for row in runs[0]["registrations"]] if runs else []
    width = 0.8 / max(2 * len(runs), 1)
    for r, run in enumerate(runs):
        rows = {row["reference"]: row for row in run["registrations"]}
        color = _MODE_COLORS.get(run["mode"], "grey")
        for s, (key, alpha, stage) in enumerate(
            (("rms_m_before", 0.35, "starting alignment"), ("rms_m_after", 1.0, "optimised"))
        ):
            offset = (2 * r + s) * width - 0.4 + width / 2
            values = [rows[job][key] for job in jobs]
            ax.bar(
                [j + offset for j in range(len(jobs))],
                values,
                width,
                color=color,
                alpha=alpha,
                label=f"{run['mode']}, {stage}",
            )
    for j, row in enumerate(runs[0]["registrations"] if runs else []):
        ax.annotate(
            f"{row['inliers']}/{row['edges']} kept",
            (j, row["rms_m_before"]),
            xytext=(0, 12),
            textcoords="offset points",
            ha="center",
            fontsize=7,
        )
    ax.set_yscale("log")
    ax.set_xticks(range(len(jobs)), [f"job of {job}" for job in jobs], fontsize=8)
    ax.set_ylabel("RMS residual of the kept inter-mission edges, m")
    bottom, top = ax.get_ylim()
    ax.set_ylim(bottom, 10 * top)  # headroom: the legend sits above the bars
    ax.grid(axis="y", alpha=0.3)
    ax.legend(loc="upper center", ncol=2, fontsize=7, framealpha=0.9)
    difference = result.get("frame_difference_m")
    same = "" if difference is None else f"; frames differ by <= {difference:.1g} m between modes"
    ax.set_title(f"registration quality{same}", fontsize=10)
