"""A mission's poses as a trajectory file: TUM or KITTI text (pure; no store).

Both formats are what trajectory evaluation tools read (evo's
`file_interface.read_tum_trajectory_file` and `read_kitti_poses_file`):

- **TUM**: one line per pose, `timestamp tx ty tz qx qy qz qw` (the TUM RGB-D
  benchmark's ground-truth format; quaternion w last, as we store it).
- **KITTI**: one line per pose, the 12 values of the 3x4 matrix `[R | t]` row
  by row (the KITTI odometry benchmark's poses format); it has no time.

The poses are the vertices' stored poses (their initial estimates), in the
mission's own frame, in index order. A 2D graph is stored lifted to 3D (z = 0,
yaw as a rotation about z), so it is written that way. TUM times are the
vertices' timestamps when every vertex has one (a CARMEN log gives them); g2o
and Kimera CSV files carry no time, and then the vertex index is the time, in
seconds (`Trajectory.timed` says which). Numbers are written in their shortest
exact form (`repr`), so reading a file back gives the stored values bit for bit.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import TextIO

from mapapi.maps.graph import MissionGraph
from mapapi.maps.se3 import Pose

log = logging.getLogger(__name__)

TRAJECTORY_FORMATS = ("tum", "kitti")


@dataclass(frozen=True)
class Trajectory:
    """A mission's poses in time order.

    Attributes:
        stamps: each pose's time in seconds: its vertex's timestamp, or its
            vertex index when not `timed`.
        poses: the poses, as (x, y, z, qx, qy, qz, qw).
        timed: the stamps are the vertices' own timestamps.
    """

    stamps: list[float]
    poses: list[Pose]
    timed: bool


def trajectory_of(graph: MissionGraph) -> Trajectory:
    """The vertices of `graph` in index order, timed by their timestamps when
    every vertex has one, else by their index (a vertex without a time among
    timed ones is logged: a mixed clock cannot be written as one)."""
    indices = sorted(graph.vertices)
    poses = [graph.vertices[i] for i in indices]
    stamps = graph.timestamps
    timed = bool(indices) and all(i in stamps for i in indices)
    if stamps and not timed:
        log.warning(
            "mission %s: %d of %d vertices have no timestamp; their indices are the time",
            graph.name,
            len(indices) - sum(1 for i in indices if i in stamps),
            len(indices),
        )
    times = [stamps[i] for i in indices] if timed else [float(i) for i in indices]
    return Trajectory(times, poses, timed)


def _number(value: float) -> str:
    return repr(float(value))


def write_tum(trajectory: Trajectory, out: TextIO) -> int:
    """Write `timestamp tx ty tz qx qy qz qw` per pose; returns the poses written."""
    for stamp, pose in zip(trajectory.stamps, trajectory.poses, strict=True):
        out.write(" ".join(map(_number, (stamp, *pose))) + "\n")
    return len(trajectory.poses)


def rotation_matrix(pose: Pose) -> tuple[tuple[float, float, float], ...]:
    """The 3x3 rotation of a pose's unit quaternion, row by row."""
    _, _, _, x, y, z, w = pose
    return (
        (1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)),
        (2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)),
        (2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)),
    )


def write_kitti(trajectory: Trajectory, out: TextIO) -> int:
    """Write the 3x4 matrix `[R | t]` of each pose, row-major, one pose a line;
    returns the poses written."""
    for pose in trajectory.poses:
        rows = rotation_matrix(pose)
        values = [v for row, t in zip(rows, pose[:3], strict=True) for v in (*row, t)]
        out.write(" ".join(map(_number, values)) + "\n")
    return len(trajectory.poses)
