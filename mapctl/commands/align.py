"""`mapctl align`: place missions in one shared world frame (issue 17 §1)."""

from __future__ import annotations

import math
from typing import Any

import click

from mapctl.commands.maps import missions_option
from mapctl.session import Session, json_option, pass_session


def _turn_degrees(transform: list[float]) -> float:
    """How far a pose (x, y, z, qx, qy, qz, qw) turns, about whatever axis, in
    degrees (the datasets' up axes differ: no one axis is yaw)."""
    return math.degrees(2 * math.acos(min(1.0, abs(transform[6]))))


def _row(frame: dict[str, Any]) -> tuple[str, ...]:
    x, y, z = frame["transform"][:3]
    sigma = math.sqrt(max(frame["covariance"][0] + frame["covariance"][6], 0.0))  # xx + yy
    tied = f"same as {frame['duplicate_of']}" if frame["duplicate_of"] else str(frame["edges"])
    return (
        frame["mission"],
        f"{x:.2f} {y:.2f} {z:.2f}",
        f"{_turn_degrees(frame['transform']):.1f}",
        f"{sigma:.3f}",
        tied,
    )


@click.command("align")
@missions_option("Align", "every pose graph held here")
@click.option(
    "--anchor",
    help="The mission whose frame is the world (default: the one with the most "
    "inter-mission edges).",
)
@click.option("--message", help="The commit message (default: says what was aligned).")
@json_option
@pass_session
def align(
    session: Session,
    names: tuple[str, ...],
    anchor: str | None,
    message: str | None,
    as_json: bool,
) -> None:
    """Place missions in one shared `world` frame from the edges between them, and
    commit where each lies (its `frames` row).

    gtsam optimises the missions' poses together with a robust loss (GNC), so
    wrong inter-robot edges are weighed out. Missions with no chain of edges to
    the anchor stay unaligned and are listed; a mission that repeats another
    (same robot, same content) takes that one's frame. The result is committed
    through the view (`--view`), like `mapctl commit`: exits 3 when another
    peer aligned a mission meanwhile, the conflicts kept for `mapctl resolve`.
    """
    from mapctl import render
    from mapctl.commands.view import call_committing

    info = call_committing(
        session,
        as_json,
        "align",
        missions=list(names) or None,
        anchor=anchor,
        message=message or "",
    )
    if as_json:
        render.emit_json(info)
        return
    rows = [_row(f) for f in info["frames"]]
    title = f"missions in the world frame (anchor {info['anchor']})"
    render.table(title, ["mission", "x y z (m)", "turn (°)", "sd x+y (m)", "edges kept"], rows)
    before, after = info["rms_before"], info["rms_after"]
    if info["edges"]:
        render.line(
            f"{info['inliers']} of {info['edges']} inter-mission edges kept; their RMS residual "
            f"{before['metres']:.2f} m / {before['degrees']:.1f}° before, "
            f"{after['metres']:.3f} m / {after['degrees']:.2f}° after"
        )
    if info["unaligned"]:
        render.line(
            f"not joined to {info['anchor']}, left unaligned: {', '.join(info['unaligned'])}",
            "yellow",
        )
    if info["commit"]:
        render.line(f"[{info['commit'][:8]}] time {info['time']}: {info['message']}", "green")


def register(cli: click.Group) -> None:
    """Add this module's commands to `cli`."""
    cli.add_command(align)
