"""Top-down pictures of missions: trajectories, loop closures, inter-robot edges,
landmarks (small crosses), point clouds and a query box, as a PNG.

The view looks down on the map from above (`view_axes`: up given, or told by
the poses' own convention, else the axis along which the map is thinnest: z for
the Intel and garage graphs and the room scan, -y for the tunnels set, recorded
by cameras), its axes in metres named x and y as in a frame whose z is up, each
with the map's own axis it shows. A picture of point clouds alone is
rendered by open3d offscreen where a renderer works (`render3d`), else, and
for everything else, drawn with matplotlib's Agg backend (no display needed).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mapapi.core.errors import UsageError
from mapapi.lookup.spatial import BBox
from mapapi.maps.cloud import PointCloud
from mapapi.maps.graph import EdgeKind, MissionGraph
from mapapi.maps.view_axes import AXES, Z_UP, Up, choose_up, plane_axes

log = logging.getLogger(__name__)

MAX_SCATTER = 200_000  # points drawn per picture: more only blurs and slows
_SEED = 7  # the subsample of a large cloud is the same on every run
_PALETTE = [f"C{i}" for i in range(10) if i != 7]  # C7 is grey: kept for the edges' web


@dataclass(frozen=True)
class PlotResult:
    """What `plot_map` drew: the renderer, the map's up it looked down along
    (`x`, `-y`...) and the missions."""

    renderer: str
    up: str
    missions: list[str]


def plot_map(
    output: str | Path,
    graphs: Sequence[MissionGraph] = (),
    clouds: Sequence[PointCloud] = (),
    box: BBox | None = None,
    up: str = "auto",
    *,
    zoom: bool = False,
    title: str | None = None,
    labels: Mapping[str, str] | None = None,
) -> PlotResult:
    """Write a top-down PNG of `graphs` and `clouds`, with `box` outlined.

    Args:
        zoom: show the box and its surroundings only (a query's close-up).
        title: above the picture (default: the axis it looks down).
        labels: mission name -> its legend entry (default: its robot).

    Raises:
        UsageError: nothing to draw, or a bad `up`.
    """
    boxes = [b for b in (*(g.bbox() for g in graphs), *(c.bbox() for c in clouds)) if b]
    if not boxes:
        raise UsageError("nothing to plot: the missions chosen have no vertices or points")
    poses = [np.array([g.vertices[k] for k in sorted(g.vertices)]) for g in graphs if g.vertices]
    looking = choose_up(boxes + ([box] if box else []), up, poses)
    names = [g.name for g in graphs] + [c.name for c in clouds]
    if zoom and box is None:
        raise UsageError("zoom needs a box to zoom to")
    if clouds and not graphs:
        from mapapi.maps.render3d import render_cloud

        points = np.concatenate([c.points for c in clouds])
        if not zoom and render_cloud(points, output, box=box, up=looking):
            return PlotResult("open3d", looking.name, names)
    _draw(output, graphs, clouds, box, looking, zoom=zoom, title=title, labels=labels or {})
    return PlotResult("matplotlib", looking.name, names)


def _draw(
    output: str | Path,
    graphs: Sequence[MissionGraph],
    clouds: Sequence[PointCloud],
    box: BBox | None,
    up: Up,
    *,
    zoom: bool,
    title: str | None,
    labels: Mapping[str, str],
) -> None:
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:
        raise UsageError(
            "plots need matplotlib; install it with `pip install 'mapapi[plot]'`"
        ) from None

    figure = Figure(figsize=(9, 8), dpi=120)
    FigureCanvasAgg(figure)
    ax = figure.add_subplot()
    u, v = plane_axes(up)
    for cloud in clouds:
        _scatter(ax, figure, cloud, u, v, up)
    _trajectories(ax, graphs, u, v, labels)
    _landmarks(ax, graphs, u, v)
    if box is not None:
        _inside(ax, graphs, box, u, v)
        _box(ax, box, u, v)
    ax.set_xlabel(axis_label("x", u, up))
    ax.set_ylabel(axis_label("y", v, up))
    ax.set_aspect("equal", adjustable="box" if zoom else "datalim")
    if zoom and box is not None:
        _zoom(ax, box, u, v)
    ax.set_title(title or f"top-down view (up: the map's {up.name})")
    ax.grid(True, linewidth=0.3, alpha=0.5)
    if ax.get_legend_handles_labels()[0]:
        # beside the map, not on it: eight robots' entries would hide a corner of it
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="small", markerscale=2)
    _scale_bar(ax)
    figure.tight_layout()
    figure.savefig(str(output), bbox_inches="tight")  # the legend beside the map included


def _scale_bar(ax: Any) -> None:
    """A bar of a round length (1, 2 or 5 times a power of ten metres, about a
    fifth of the view's width) in the lower right corner."""
    from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar

    ax.figure.canvas.draw()  # the limits an equal aspect gives are known once drawn
    width = abs(ax.get_xlim()[1] - ax.get_xlim()[0])
    if not width > 0:
        return
    power = 10 ** math.floor(math.log10(width / 5))
    length = max(s * power for s in (1, 2, 5) if s * power <= width / 4) if power else 0
    if length:
        bar = AnchoredSizeBar(
            ax.transData,
            length,
            f"{length:g} m",
            "lower right",
            pad=0.5,
            frameon=False,
            size_vertical=0,
        )
        ax.add_artist(bar)


def axis_label(name: str, axis: int, up: Up) -> str:
    """A picture axis's label: `name` in metres, and the map's axis it shows
    where the map's frame does not have z up."""
    if up == Z_UP:
        return f"{name} [m]"
    return f"{name} [m] (map {AXES[axis]})"


def _scatter(ax: Any, figure: Any, cloud: PointCloud, u: int, v: int, up: Up) -> None:
    points = cloud.points
    if len(points) > MAX_SCATTER:
        keep = np.random.default_rng(_SEED).choice(len(points), MAX_SCATTER, replace=False)
        points = points[keep]
    drawn = ax.scatter(
        points[:, u], points[:, v], c=up.height(points), s=0.3, cmap="viridis", linewidths=0
    )
    figure.colorbar(drawn, ax=ax, label=f"{cloud.name}: height along {up.name} [m]", shrink=0.7)


def _colours(graphs: Sequence[MissionGraph]) -> dict[str, str]:
    """Mission name -> its robot's colour."""
    robots = sorted({g.robot or g.name for g in graphs})
    by_robot = {r: _PALETTE[i % len(_PALETTE)] for i, r in enumerate(robots)}
    return {g.name: by_robot[g.robot or g.name] for g in graphs}


def _trajectories(
    ax: Any, graphs: Sequence[MissionGraph], u: int, v: int, labels: Mapping[str, str]
) -> None:
    from matplotlib.collections import LineCollection

    colours = _colours(graphs)
    where = {(g.name, i): (p[u], p[v]) for g in graphs for i, p in g.vertices.items()}
    labelled: set[str] = set()
    links: list[tuple[tuple[float, float], tuple[float, float]]] = []
    for graph in graphs:
        colour = colours[graph.name]
        name = labels.get(graph.name) or graph.robot or graph.name
        label = None if name in labelled else name
        labelled.add(name)
        for n, xy in enumerate(_runs(graph, u, v)):
            ax.plot(xy[:, 0], xy[:, 1], color=colour, linewidth=1.0, label=None if n else label)
        start = where[graph.name, min(graph.vertices)]
        ax.plot(*start, marker="o", color=colour, markersize=4)
        loops = [
            (where[e.source], where[e.target])
            for e in graph.edges
            if e.kind is EdgeKind.LOOP and e.source in where and e.target in where
        ]
        ax.add_collection(LineCollection(loops, colors=colour, linewidths=0.6, alpha=0.5))
        links += [
            (where[e.source], where[e.target])
            for e in graph.edges
            if e.kind is EdgeKind.INTER_ROBOT and e.source in where and e.target in where
        ]
    if any(g.count(EdgeKind.LOOP) for g in graphs):
        ax.plot([], [], color="grey", linewidth=0.6, label="loop closures (robot's colour)")
    if links:
        ax.add_collection(
            # thin and light: a set holds thousands, most of them wrong matches
            LineCollection(links, colors="black", linewidths=0.2, alpha=0.04, linestyles="dashed")
        )
        ax.plot([], [], color="black", linewidth=0.6, linestyle="--", label="inter-robot edges")


def _landmarks(ax: Any, graphs: Sequence[MissionGraph], u: int, v: int) -> None:
    """Each mission's landmarks as small crosses in its robot's colour, above
    the trajectories (a landmark map has a few hundred; their observations
    would hide the path, so they are not drawn)."""
    colours = _colours(graphs)
    drawn = False
    for graph in graphs:
        if graph.landmarks:
            xy = np.array([(p[u], p[v]) for p in graph.landmarks.values()])
            ax.scatter(
                xy[:, 0],
                xy[:, 1],
                s=12,
                marker="+",
                linewidths=0.8,
                color=colours[graph.name],
                zorder=3,
            )
            drawn = True
    if drawn:
        ax.scatter([], [], s=12, marker="+", color="grey", label="landmarks")


def _runs(graph: MissionGraph, u: int, v: int) -> list[Any]:
    """The trajectory's (u, v) points in index order, cut where indices skip more
    than their usual step: a mission held in part (the tiles in a box) is drawn
    as the pieces held, not joined by lines across what is missing."""
    indices = np.array(sorted(graph.vertices))
    xy = np.array([(graph.vertices[i][u], graph.vertices[i][v]) for i in indices])
    # landmark ids may sit between poses' (Victoria Park: 4, landmark 5, 6): count them as steps
    steps = np.diff(np.searchsorted(np.array(sorted({*graph.vertices, *graph.landmarks})), indices))
    if not len(steps):
        return [xy]
    return np.split(xy, np.nonzero(steps > steps.min())[0] + 1)


def _inside(ax: Any, graphs: Sequence[MissionGraph], box: BBox, u: int, v: int) -> None:
    """Dot the vertices that lie in the box (in all three axes), in their robot's colour."""
    colours = _colours(graphs)
    lo, hi = np.array(box.mins), np.array(box.maxs)
    dotted = False
    for graph in graphs:
        xyz = np.array([p[:3] for p in graph.vertices.values()])
        inside = xyz[np.all((xyz >= lo) & (xyz <= hi), axis=1)]
        if len(inside):
            ax.scatter(inside[:, u], inside[:, v], s=9, color=colours[graph.name], zorder=3)
            dotted = True
    if dotted:
        ax.scatter([], [], s=9, color="grey", label="vertices in the box")


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


def _zoom(ax: Any, box: BBox, u: int, v: int, margin: float = 0.25) -> None:
    """Limit the view to the box and a margin of `margin` times its size around it."""
    lo, hi = box.mins, box.maxs
    pad = margin * max(hi[u] - lo[u], hi[v] - lo[v])
    ax.set_xlim(lo[u] - pad, hi[u] + pad)
    ax.set_ylim(lo[v] - pad, hi[v] + pad)
