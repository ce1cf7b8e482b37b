"""Missions: `export`, `missions`, `plot`, `grid` (the application layer, DESIGN §2;
`import` is `imports`')."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import click

from mapctl.session import Session, json_option, pass_session

EXPORT_FORMATS = ("g2o", "tum", "kitti", "ply", "pcd", "bag", "grid")  # maps.jobs.EXPORT_FORMATS
UP_CHOICES = ("auto", "x", "y", "z", "-x", "-y", "-z")  # mapapi.maps.view_axes.UP_CHOICES


def bbox_text(box: list[float] | None) -> str:
    """A mission's box to the metre, or "-"."""
    return "-" if box is None else " ".join(str(round(v)) for v in box)  # to the metre


def size_text(mission: dict[str, Any]) -> str:
    """A mission's size as `missions` and `import` list it."""
    if mission["vertices"] is None:
        return "?"  # held elsewhere: only its box is known here
    if "grids" in (mission.get("chunks") or {}):
        return "occupancy grid"  # its cells are counted by `mapctl grid`
    graph = f"{mission['vertices']} v + {mission['edges']} e"
    if mission.get("landmarks"):
        graph += f" + {mission['landmarks']} lm"
    if mission["points"]:  # a cloud, or a laser mission's scans
        return (
            f"{graph}, {mission['points']} points"
            if mission["vertices"]
            else f"{mission['points']} points"
        )
    return graph


def _grid_files(output: Path, info: dict[str, Any]) -> str:
    """The files a grid was written to, as `grid` and `export` say them (beside
    `output`, as the user named it)."""
    if info["tile"] is None:
        return f"{output} and {Path(info['image']).name}"
    skipped = f", {info['skipped']} all unknown left out" if info["skipped"] else ""
    return (
        f"{len(info['tiles'])} tile(s) of up to {info['tile']} x {info['tile']} cells"
        f"{skipped}, listed in {output.with_name(Path(info['path']).name)}"
    )


def _holders_text(holders: list[dict[str, Any]]) -> str:
    return ", ".join(h["name"] or h["id"][:8] for h in holders) or "?"


def frame_option(what: str, where: str = "in each mission's own frame, or in") -> Any:
    """`--frame mission|world`: the frame a command reads or takes poses in."""
    return click.option(
        "--frame",
        type=click.Choice(["mission", "world"]),
        default="mission",
        show_default=True,
        help=f"{what} {where} the shared world frame (`mapctl align` places missions there).",
    )


def _output_option(text: str) -> Any:
    """`-o/--output FILE`, required."""
    return click.option(
        "-o", "--output", required=True, type=click.Path(dir_okay=False, path_type=Path), help=text
    )


@click.command("export")
@click.argument("mission")
@_output_option(
    "The file to write: .g2o for a pose graph, .tum or .kitti for its trajectory, "
    ".ply or .pcd for a point cloud, .yaml for a nav2 map (the PGM beside it); with "
    "--format bag, the ROS 2 bag's new folder."
)
@click.option(
    "--format",
    "fmt",
    type=click.Choice(EXPORT_FORMATS),
    help="The format to write (default: by the extension; needed for .txt and for bag, "
    "a ROS 2 bag in MCAP of the poses, path and points; .yaml means grid, a nav2 map).",
)
@frame_option("Write a graph's poses")
@json_option
@pass_session
def export_map(
    session: Session, mission: str, output: Path, fmt: str | None, frame: str, as_json: bool
) -> None:
    """Write MISSION to a file: a graph as g2o (2D when it lies in the plane),
    its poses as a TUM or KITTI trajectory, a point cloud as binary PLY (or PCD),
    poses, path, points and grid as a ROS 2 bag (MCAP), its occupancy grid (stored,
    or cast from its laser scans as `mapctl grid` does) as a nav2 map."""
    from mapctl import render

    info = session.call(
        "export_map", mission=mission, path=str(output.resolve()), fmt=fmt, frame=frame
    )
    if as_json:
        render.emit_json(info)
        return
    if info["format"] == "bag":
        grid = f", a grid of {info['grid_cells']:,} cells" if info["grid_cells"] else ""
        what = (
            f"{info['poses']} poses, {info['points']} points{grid} on {', '.join(info['topics'])}"
        )
    elif info["format"] == "grid":
        cells = info["cells"]
        what = (
            f"a nav2 map of {info['width']} x {info['height']} cells of {info['resolution']} m, "
            f"image {Path(info['image']).name} ({cells['occupied']} occupied, "
            f"{cells['free']} free, {cells['unknown']} unknown)"
        )
    elif info["format"] == "g2o":
        what = f"{info['vertices']} vertices, {info['edges']} edges"
        if info.get("landmarks"):
            what += f", {info['landmarks']} landmarks"
        if info["left_out"]:
            what += f" ({info['left_out']} edges to other missions left out)"
    elif "poses" in info:
        clock = "timed" if info["time"] == "timestamp" else "no timestamps: the index is the time"
        what = f"{info['poses']} poses ({clock})"
    else:
        what = f"{info['points']} points"
    render.line(f"wrote mission {mission} to {output}: {what}")


@click.command("missions")
@click.option(
    "--swarm", is_flag=True, help="Also list the missions other peers hold (needs a running peer)."
)
@frame_option("Give each mission's box")
@json_option
@pass_session
def missions(session: Session, swarm: bool, frame: str, as_json: bool) -> None:
    """List the missions held here: robot, size (vertices + edges, or points),
    box (to the metre) and holders. In the world frame a mission not aligned
    yet has no box ("-")."""
    from mapctl import render

    info = session.call("missions", swarm=swarm, frame=frame)
    if as_json:
        render.emit_json(info)
        return
    columns = ["name", "robot", "size", "bbox", "holders"] + (["here"] if swarm else [])
    rows = [
        (
            m["name"],
            m["robot"] or "-",
            size_text(m),
            bbox_text(m["bbox"]),
            _holders_text(m["holders"]),
            "yes" if m["held"] else "no",
        )[: len(columns)]
        for m in info["missions"]
    ]
    render.table("missions", columns, rows)


def _bbox_option(text: str) -> Any:
    """`--bbox XMIN YMIN ZMIN XMAX YMAX ZMAX`."""
    return click.option(
        "--bbox", nargs=6, type=float, metavar="XMIN YMIN ZMIN XMAX YMAX ZMAX", help=text
    )


def missions_option(verb: str, default: str) -> Any:
    """`-m/--mission NAME`, repeatable, shell patterns allowed."""
    return click.option(
        "--mission",
        "-m",
        "names",
        multiple=True,
        help=f"{verb} this mission, or those matching a pattern like 'tunnels-*' (repeat; "
        f"default: {default}).",
    )


@click.command("plot")
@_bbox_option("Outline this box (and, without --mission, draw the missions it overlaps).")
@missions_option("Draw", "every mission held here")
@click.option(
    "--up",
    type=click.Choice(UP_CHOICES),
    default="auto",
    show_default=True,
    help="The map's up, looked down along from above (auto: as the poses' body convention "
    "tells, else the axis along which the map is thinnest); -y for a camera's frame.",
)
@click.option("--zoom", is_flag=True, help="Show the --bbox box and its surroundings only.")
@click.option("--title", help="The picture's title (default: the map's up).")
@frame_option("Draw the trajectories")
@_output_option("The PNG to write.")
@json_option
@pass_session
def plot(
    session: Session,
    bbox: tuple[float, ...] | None,
    names: tuple[str, ...],
    up: str,
    zoom: bool,
    title: str | None,
    frame: str,
    output: Path,
    as_json: bool,
) -> None:
    """Draw a top-down PNG of missions: trajectories coloured per robot, loop
    closures, inter-robot edges, point clouds and the query box (with the
    vertices inside it dotted).

    Point clouds alone are rendered by open3d offscreen where a renderer works,
    else (and with graphs) drawn with matplotlib.
    """
    from mapctl import render

    info = session.call(
        "plot_map",
        path=str(output.resolve()),
        bbox=list(bbox) if bbox else None,
        missions=list(names) or None,
        up=up,
        zoom=zoom,
        title=title,
        frame=frame,
    )
    if as_json:
        render.emit_json(info)
        return
    render.line(
        f"wrote {output}: {len(info['missions'])} mission(s), seen from above along {info['up']} "
        f"({info['renderer']})"
    )


@click.command("grid")
@_output_option(
    "The nav2 map YAML to write; the PGM image goes beside it (same name, .pgm). With --tile, "
    "NAME.yaml names the tiles and their index, NAME.tiles.yaml."
)
@missions_option("Cast the scans of", "every mission held here with laser scans")
@_bbox_option("The grid covers this box's x and y (default: every scan's rays).")
@click.option(
    "--resolution",
    type=click.FloatRange(min=0, min_open=True),
    default=None,
    help="The side of a cell, in metres (scans: 0.05 by default; a stored grid keeps its own).",
)
@frame_option("Cast the scans (or write the stored grids)")
@click.option(
    "--tile",
    type=click.IntRange(min=1),
    metavar="CELLS",
    help="Cut the map into nav2 maps of at most CELLS x CELLS cells, NAME_r{row}_c{col}.yaml "
    "(row 0 the bottom), skipping tiles all unknown, listed in NAME.tiles.yaml.",
)
@json_option
@pass_session
def grid(
    session: Session,
    output: Path,
    names: tuple[str, ...],
    bbox: tuple[float, ...] | None,
    resolution: float | None,
    frame: str,
    tile: int | None,
    as_json: bool,
) -> None:
    """Write an occupancy grid of laser missions, or the stored grids of grid
    missions, for nav2's map_server: a PGM (0 occupied, 254 free, 205 unknown)
    and its YAML.

    Each ray of each scan runs from the pose that took it to its return: the
    return's cell is hit, the cells before it passed; a cell hit in more than
    65 % of the rays reaching it is occupied, in fewer than 25 % free. Several
    missions share one grid in the world frame (`mapctl align`). A stored
    grid's cells (a bag's occupancy grid) are written as they are: at least
    65 occupied, below 25 free; a grid turned at its origin, or placed in the
    world frame (a `frames` row), is resampled along the frame's axes.
    """
    from mapctl import render

    info = session.call(
        "grid_map",
        path=str(output.resolve()),
        missions=list(names) or None,
        bbox=list(bbox) if bbox else None,
        resolution=resolution,
        frame=frame,
        tile=tile,
    )
    if as_json:
        render.emit_json(info)
        return
    cells = info["cells"]
    source = f"{info['scans']} scans of" if info["scans"] else "the stored grid of"
    render.line(
        f"wrote {_grid_files(output, info)}: {info['width']} x {info['height']} "
        f"cells of {info['resolution']} m from {source} "
        f"{', '.join(info['missions'])} ({cells['occupied']} occupied, {cells['free']} free, "
        f"{cells['unknown']} unknown) in {info['seconds']:.2f} s"
    )
    if info["without_scans"]:
        render.line(f"no laser scans in: {', '.join(info['without_scans'])}", "yellow")


def register(cli: click.Group) -> None:
    """Add this module's commands to `cli`."""
    for command in (export_map, missions, plot, grid):
        cli.add_command(command)
