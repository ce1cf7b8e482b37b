"""Top-down pictures of missions: trajectories, loop closures, inter-robot edges,
point clouds and a query box, as a PNG.

The view looks down the "up" axis, by default the axis along which everything
drawn is thinnest (z for the Intel and garage graphs and the room scan, y for
the tunnels set, recorded in camera axes). A picture of point clouds alone is
rendered by open3d offscreen where a renderer works (`render3d`), else, and
for everything else, drawn with matplotlib's Agg backend (no display needed).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mapapi.errors import UsageError
from mapapi.maps.cloud import PointCloud
from mapapi.maps.graph import EdgeKind, MissionGraph
from mapapi.spatial import BBox

log = logging.getLogger(__name__)

AXES = "xyz"
MAX_SCATTER = 200_000  # points drawn per picture: more only blurs and slows
_SEED = 7  # the subsample of a large cloud is the same on every run


@dataclass(frozen=True)
class PlotResult:
    """What `plot_map` drew: the renderer, the axis it looked down and the missions."""

    renderer: str
    up: str
    missions: list[str]


def choose_up(boxes: Sequence[BBox], up: str = "auto") -> int:
    """The index of the axis to look down: `up` if it names one, else the axis
    along which the boxes' union is thinnest.

    Raises:
        UsageError: `up` is not auto, x, y or z.
    """
    if up in AXES:
        return AXES.index(up)
    if up != "auto":
        raise UsageError(f"--up must be auto, x, y or z, not {up!r}")
    if not boxes:
        return 2
    union = BBox.enclosing(boxes)
    extent = [hi - lo for lo, hi in zip(union.mins, union.maxs, strict=True)]
    return int(np.argmin(extent))


def plane_axes(up: int) -> tuple[int, int]:
    """The two axes of the picture when looking down axis `up` (right-handed)."""
    return {0: (1, 2), 1: (2, 0), 2: (0, 1)}[up]


def plot_map(
    output: str | Path,
    graphs: Sequence[MissionGraph] = (),
    clouds: Sequence[PointCloud] = (),
    box: BBox | None = None,
    up: str = "auto",
) -> PlotResult:
    """Write a top-down PNG of `graphs` and `clouds`, with `box` outlined.

    Raises:
        UsageError: nothing to draw, or a bad `up`.
    """
    boxes = [b for b in (*(g.bbox() for g in graphs), *(c.bbox() for c in clouds)) if b]
    if not boxes:
        raise UsageError("nothing to plot: the missions chosen have no vertices or points")
    axis = choose_up(boxes + ([box] if box else []), up)
    names = [g.name for g in graphs] + [c.name for c in clouds]
    if clouds and not graphs:
        from mapapi.maps.render3d import render_cloud

        points = np.concatenate([c.points for c in clouds])
        if render_cloud(points, output, box=box, up=axis):
            return PlotResult("open3d", AXES[axis], names)
    _draw(output, graphs, clouds, box, axis)
    return PlotResult("matplotlib", AXES[axis], names)


def _draw(
    output: str | Path,
    graphs: Sequence[MissionGraph],
    clouds: Sequence[PointCloud],
    box: BBox | None,
    up: int,
) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    figure = Figure(figsize=(9, 8), dpi=120)
    FigureCanvasAgg(figure)
    ax = figure.add_subplot()
    u, v = plane_axes(up)
    for cloud in clouds:
        _scatter(ax, figure, cloud, u, v, up)
    _trajectories(ax, graphs, u, v)
    if box is not None:
        _box(ax, box, u, v)
    ax.set_xlabel(f"{AXES[u]} [m]")
    ax.set_ylabel(f"{AXES[v]} [m]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_title(f"top-down view (looking down {AXES[up]})")
    ax.grid(True, linewidth=0.3, alpha=0.5)
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="best", fontsize="small", markerscale=2)
    figure.tight_layout()
    figure.savefig(str(output))


def _scatter(ax: Any, figure: Any, cloud: PointCloud, u: int, v: int, up: int) -> None:
    points = cloud.points
    if len(points) > MAX_SCATTER:
        keep = np.random.default_rng(_SEED).choice(len(points), MAX_SCATTER, replace=False)
        points = points[keep]
    drawn = ax.scatter(
        points[:, u], points[:, v], c=points[:, up], s=0.3, cmap="viridis", linewidths=0
    )
    figure.colorbar(drawn, ax=ax, label=f"{cloud.name}: {AXES[up]} [m]", shrink=0.7)


def _trajectories(ax: Any, graphs: Sequence[MissionGraph], u: int, v: int) -> None:
    from matplotlib.collections import LineCollection

    robots = sorted({g.robot or g.name for g in graphs})
    colours = {r: f"C{i % 10}" for i, r in enumerate(robots)}
    where = {(g.name, i): (p[u], p[v]) for g in graphs for i, p in g.vertices.items()}
    labelled: set[str] = set()
    links: list[tuple[tuple[float, float], tuple[float, float]]] = []
    for graph in graphs:
        robot = graph.robot or graph.name
        colour = colours[robot]
        xy = np.array([(p[u], p[v]) for _, p in sorted(graph.vertices.items())])
        label = None if robot in labelled else robot
        labelled.add(robot)
        ax.plot(xy[:, 0], xy[:, 1], color=colour, linewidth=1.0, label=label)
        ax.plot(xy[0, 0], xy[0, 1], marker="o", color=colour, markersize=4)
        loops = [(where[e.source], where[e.target]) for e in graph.edges if e.kind is EdgeKind.LOOP]
        ax.add_collection(LineCollection(loops, colors=colour, linewidths=0.4, alpha=0.35))
        links += [
            (where[e.source], where[e.target])
            for e in graph.edges
            if e.kind is EdgeKind.INTER_ROBOT and e.source in where and e.target in where
        ]
    if any(g.count(EdgeKind.LOOP) for g in graphs):
        ax.plot([], [], color="grey", linewidth=0.6, label="loop closures")
    if links:
        ax.add_collection(
            LineCollection(links, colors="black", linewidths=0.3, alpha=0.15, linestyles="dashed")
        )
        ax.plot([], [], color="black", linewidth=0.6, linestyle="--", label="inter-robot edges")


def _box(ax: Any, box: BBox, u: int, v: int) -> None:
    from matplotlib.patches import Rectangle

    lo, hi = box.mins, box.maxs
    ax.add_patch(
        Rectangle(
            (lo[u], lo[v]),
            hi[u] - lo[u],
            hi[v] - lo[v],
            fill=False,
            edgecolor="red",
            linewidth=2,
            label="query box",
        )
    )
    ax.update_datalim([(lo[u], lo[v]), (hi[u], hi[v])])
