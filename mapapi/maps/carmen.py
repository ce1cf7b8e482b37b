"""CARMEN laser logs (`.clf`, plain or bzip2-compressed) as a laser mission.

A log holds one message a line (`shared/datasets/README.md` §6):

- `FLASER n r1 .. rn x y theta odom_x odom_y odom_theta ipc_timestamp host
  logger_timestamp`: a front laser scan of n ranges over 180°, taken at the
  laser's pose (x, y, theta) when the robot's odometry said (odom_x, ...);
- `ODOM x y theta tv rv accel ipc_timestamp host logger_timestamp`;
- others (`PARAM`, `SYNC`, `RLASER`, `TRUEPOS`, `#` comments) say nothing about
  the front scans' trajectory and are skipped.

The mission (`read_carmen`) has a vertex per scan at its odometry pose, timed
by the scan's `ipc_timestamp`, an odometry edge between consecutive scans
(their relative pose, information `INFORMATION`), and the scan's returns
projected from the laser's pose (`mapapi.maps.laser`). A log without FLASER
records gives the trajectory of its ODOM records, without scans; in a log with
scans, ODOM records are not read past the first scan. The log is
read line by line (a 16 MB log never sits in memory as text); an error names
its line. `mapbench.carmen` makes benchmark graphs with the same reader.
"""

from __future__ import annotations

import bz2
import math
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

import numpy as np

from mapapi.maps.errors import MapImportError
from mapapi.maps.graph import EdgeKind, GraphEdge, Origin
from mapapi.maps.laser import LaserMission, beam_angles, project_scan
from mapapi.maps.se3 import from_se2, lift_information

Progress = Callable[[int, int], None]  # (lines read, 0: the total is unknown while streaming)
Pose2 = tuple[float, float, float]  # x, y, theta

INFORMATION = (400.0, 0.0, 0.0, 400.0, 0.0, 3283.0)
"""The upper triangle of every odometry edge's 3x3 information matrix: 5 cm and
1 degree standard deviation (a log states none)."""

MAX_RANGE = 80.0
"""Ranges at or beyond this (metres) are no returns: the SICK lasers of these
logs reach 80 m, and CARMEN writes a missing return as 81.83 or 81.91."""

_PROGRESS_EVERY = 10_000


@dataclass(frozen=True, slots=True)
class Scan:
    """One FLASER record.

    Attributes:
        line: its line in the log (1-based).
        ranges: the n ranges, metres.
        laser: the laser's pose when it scanned.
        odometry: the robot's odometry pose then.
        timestamp: its `ipc_timestamp`, seconds.
    """

    line: int
    ranges: np.ndarray
    laser: Pose2
    odometry: Pose2
    timestamp: float


@dataclass(frozen=True, slots=True)
class Odometry:
    """One ODOM record: its line, pose and `ipc_timestamp`."""

    line: int
    pose: Pose2
    timestamp: float


def open_log(path: Path) -> TextIO:
    """A log's text, decompressed on the fly when its name ends in `.bz2`."""
    if path.suffix.lower() == ".bz2":
        return bz2.open(path, "rt", encoding="ascii")
    return path.open(encoding="ascii")


def read_records(
    lines: Iterable[str], source: str = "", progress: Progress | None = None
) -> Iterator[Scan | Odometry]:
    """The FLASER records of a log's lines, in order, and the ODOM records before
    the first FLASER: once a scan is seen, the scans carry the odometry, and the
    ODOM records (twice as many in the Intel log) are passed over unread.

    Raises:
        MapImportError: a malformed FLASER line, or ODOM line read (the message names it).
    """
    number, scanned = 0, False
    for number, line in enumerate(lines, 1):
        if progress is not None and number % _PROGRESS_EVERY == 0:
            progress(number, 0)
        tag, _, rest = line.partition(" ")
        if tag == "FLASER":
            scanned = True
            yield _scan(rest.split(), number, source)
        elif tag == "ODOM" and not scanned:
            yield _odometry(rest.split(), number, source)
    if progress is not None:
        progress(number, number)


def _scan(fields: list[str], line: int, source: str) -> Scan:
    try:
        n = int(fields[0]) if fields else -1
        if n < 0 or len(fields) < n + 8:
            raise ValueError(
                f"{max(n, 0)} ranges need {max(n, 0) + 8} values after the tag "
                "(n, the ranges, two poses, a timestamp), "
                f"found {len(fields)}"
            )
        ranges = np.array(fields[1 : n + 1], dtype=np.float64)  # C parsing: 2.5M numbers in all
        x, y, theta, ox, oy, otheta, stamp = (float(v) for v in fields[n + 1 : n + 8])
    except ValueError as exc:
        raise MapImportError(f"FLASER: {exc}", source=source, line=line) from None
    if not (np.isfinite(ranges).all() and all(map(math.isfinite, (x, y, theta, ox, oy, otheta)))):
        raise MapImportError("FLASER: a value is not a finite number", source=source, line=line)
    return Scan(line, ranges, (x, y, theta), (ox, oy, otheta), stamp)


def _odometry(fields: list[str], line: int, source: str) -> Odometry:
    try:
        if len(fields) < 7:
            raise ValueError(
                f"expected x y theta tv rv accel timestamp, found {len(fields)} values"
            )
        x, y, theta = (float(v) for v in fields[:3])
        stamp = float(fields[6])
    except ValueError as exc:
        raise MapImportError(f"ODOM: {exc}", source=source, line=line) from None
    if not all(map(math.isfinite, (x, y, theta))):
        raise MapImportError("ODOM: a value is not a finite number", source=source, line=line)
    return Odometry(line, (x, y, theta), stamp)


def relative_se2(a: Pose2, b: Pose2) -> Pose2:
    """The pose of `b` in the frame of `a` (both planar), its angle in (-pi, pi]."""
    c, s = math.cos(a[2]), math.sin(a[2])
    dx, dy = b[0] - a[0], b[1] - a[1]
    dtheta = math.atan2(math.sin(b[2] - a[2]), math.cos(b[2] - a[2]))
    return (c * dx + s * dy, -s * dx + c * dy, dtheta)


def log_name(path: Path) -> str:
    """A log's mission name: its file name less `.bz2` and `.clf` (intel.clf.bz2 -> intel)."""
    name = path.name
    for suffix in (".bz2", ".clf"):
        if name.lower().endswith(suffix):
            name = name[: -len(suffix)]
    return name or path.name


def read_carmen(
    path: str | Path,
    mission: str | None = None,
    robot: str = "",
    *,
    max_range: float = MAX_RANGE,
    progress: Progress | None = None,
) -> LaserMission:
    """Read a CARMEN log as one laser mission (see the module docstring), named
    after the file unless `mission`.

    Raises:
        MapImportError: a malformed record (the message names the line), or a
            log with neither FLASER nor ODOM records.
    """
    path = Path(path)
    name = mission or log_name(path)
    laser = LaserMission(name, robot, f"{name}/odom", planar=True)
    trajectory = _Trajectory(laser)
    odometry: list[Odometry] = []  # the trajectory if the log turns out to have no scans
    angles: dict[int, np.ndarray] = {}
    with open_log(path) as lines:
        for record in read_records(lines, str(path), progress):
            if isinstance(record, Odometry):
                odometry.append(record)
                continue
            index = trajectory.add(record.odometry, record.timestamp, record.line)
            count = len(record.ranges)
            if count not in angles:
                angles[count] = beam_angles(count)
            points = project_scan(record.ranges, angles[count], record.laser, max_range)
            if len(points):
                laser.scans[index] = points
    if not laser.vertices:
        for odom in odometry:
            trajectory.add(odom.pose, odom.timestamp, odom.line)
    if not laser.vertices:
        raise MapImportError("no FLASER or ODOM record: no trajectory to import", source=str(path))
    return laser


class _Trajectory:
    """Adds a mission's poses in order, each with the odometry edge from the one
    before, computed from the poses as the log gives them (not as stored: the
    yaw back from a quaternion is off in the last bits)."""

    _INFORMATION = lift_information(INFORMATION)

    def __init__(self, laser: LaserMission) -> None:
        self.laser = laser
        self.last: Pose2 | None = None

    def add(self, pose: Pose2, stamp: float, line: int) -> int:
        """Add the next vertex at `pose`, taken at `stamp`, read on `line`; its index."""
        laser = self.laser
        index = len(laser.vertices)
        laser.vertices[index] = from_se2(*pose)
        laser.timestamps[index] = stamp
        laser.origins[index] = Origin(line)
        if self.last is not None:
            relative = from_se2(*relative_se2(self.last, pose))
            ends = (laser.name, index - 1), (laser.name, index)
            laser.edges.append(
                GraphEdge(*ends, relative, self._INFORMATION, EdgeKind.ODOMETRY, Origin(line))
            )
        self.last = pose
        return index
