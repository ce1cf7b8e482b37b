"""`mapctl import`: read a map file into missions (the application layer, DESIGN §2)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import click

from mapctl.commands.maps import bbox_text, size_text
from mapctl.session import Session, json_option, pass_session

FORMATS = ("g2o", "kimera-csv", "gtsam-landmarks", "ply", "pcd", "carmen", "rosbag")


@click.command("import")
@click.argument("file", type=click.Path(exists=True, path_type=Path))
@click.option(
    "--format",
    "fmt",
    type=click.Choice(FORMATS),
    help="The file's format (default: by extension; a folder is a ROS 2 bag when it holds "
    "metadata.yaml, a DGS set of <n>.g2o files or a Kimera set; a .txt file GTSAM landmark "
    "text if its first record is one).",
)
@click.option(
    "--mission",
    help="The mission's name (default: the file's); a prefix for a Kimera set or for "
    "per-robot g2o (default robot-).",
)
@click.option("--robot", help="The robot's name (sources of one mission only).")
@click.option(
    "--voxel",
    type=click.FloatRange(0),
    help="Point clouds: keep one point per voxel of this side in metres; 0 keeps all "
    "[default: 0.05; for a bag's clouds 0].",
)
@click.option(
    "--topics",
    "topics",
    multiple=True,
    metavar="TOPIC[,TOPIC...]",
    help="ROS bags: read these topics only (repeat, or separate with commas; default: every "
    "pose, path, odometry and point cloud topic).",
)
@click.option(
    "--tf-frame",
    metavar="FRAME",
    help="ROS bags: place the point clouds in this TF frame (default: the first odometry "
    "topic's frame, else the first pose topic's).",
)
@click.option(
    "--scan-match",
    is_flag=True,
    help="Laser logs: correct the odometry by matching each scan to those before it, so "
    "walls stay where they are (the Intel log: about 40 s).",
)
@json_option
@pass_session
def import_map(
    session: Session,
    file: Path,
    fmt: str | None,
    mission: str | None,
    robot: str | None,
    voxel: float | None,
    topics: tuple[str, ...],
    tf_frame: str | None,
    scan_match: bool,
    as_json: bool,
) -> None:
    """Import a map FILE: g2o pose graph (one mission per robot when its ids are
    GTSAM Symbol keys), Kimera-Multi CSV set, GTSAM landmark text, PLY or PCD
    cloud, CARMEN laser log (.clf, .clf.bz2), ROS bag (.bag, or a ROS 2 bag's
    folder: one mission per pose, point cloud or occupancy grid topic; clouds
    placed through /tf in the odometry's frame, or in --tf-frame's).

    Each mission is one commit, in new chunks (one per table); a malformed file
    stops with the line it failed on, and nothing is committed.
    """
    from mapctl import render

    path = str(file.resolve())
    chosen = [t for text in topics for t in text.split(",") if t]
    args: dict[str, Any] = {"path": path, "fmt": fmt, "mission": mission, "robot": robot}
    args |= {"voxel": voxel, "topics": chosen or None, "scan_match": scan_match}
    if tf_frame is not None:
        args["tf_frame"] = tf_frame
    with render.transfer(f"importing {file.name}") as show:
        info = session.call_with_progress(
            "import_map",
            args,
            ("import_progress", {"path": path}),
            lambda state: show(state["done"], state["total"]),
        )
    if as_json:
        render.emit_json(info)
        return
    rows = [
        (m["name"], m["robot"] or "-", size_text(m), bbox_text(m["bbox"]), m["commit"][:8])
        for m in info["missions"]
    ]
    title = f"imported {file.name} ({info['format']})"
    render.table(title, ["name", "robot", "size", "bbox", "commit"], rows)
    rate = f" ({info['elements_per_s']:,} elements/s)" if info["elements"] else ""
    render.line(f"{len(info['missions'])} mission(s) in {info['seconds']:.2f} s{rate}")
    for m in info["missions"]:
        if m.get("scan_match"):
            matched = m["scan_match"]
            render.line(
                f"{m['name']}: {matched['keyframes']:,} scans matched; the odometry had drifted "
                f"up to {matched['largest']:.2f} m"
            )
        for warning in m["warnings"]:
            render.warning(f"{m['name']}: {warning}")


def register(cli: click.Group) -> None:
    """Add this module's command to `cli`."""
    cli.add_command(import_map)
