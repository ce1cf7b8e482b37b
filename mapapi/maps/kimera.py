"""The Kimera-Multi / dpgo_ros multi-robot CSV (`robotN/measurements.csv`).

Each row is a relative SE(3) measurement between two (robot, pose) vertices
(`shared/datasets/README.md` §1). We make one mission per robot; its
trajectory comes from chaining its odometry (`pose_dst == pose_src + 1`, same
robot). Intra-robot loops stay loops; an inter-robot edge is owned by the
source robot's mission and kept once although both robots' files list it
(the first row read wins; the copies differ at most in `weight`): the rules of
every multi-robot set, `mapapi.maps.robots`.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Callable, Iterable
from pathlib import Path

from mapapi.maps.errors import MapImportError
from mapapi.maps.graph import MissionGraph, Origin
from mapapi.maps.robots import RobotMissions
from mapapi.maps.se3 import isotropic_information

Progress = Callable[[int, int], None]  # (rows read, 0 while the total is unknown)

HEADER = [
    "robot_src",
    "pose_src",
    "robot_dst",
    "pose_dst",
    "qx",
    "qy",
    "qz",
    "qw",
    "tx",
    "ty",
    "tz",
    "kappa",
    "tau",
    "is_known_inlier",
    "weight",
]
FILE_NAME = "measurements.csv"


class KimeraReader:
    """Accumulates the rows of one or more robots' files; `graphs()` finishes.

    Args:
        prefix: prepended to each mission name (`{prefix}robot{N}`), so two data
            sets can share a repository.
    """

    def __init__(self, prefix: str = "", progress: Progress | None = None) -> None:
        self.prefix = prefix
        self.progress = progress
        self.rows = 0
        self._missions = RobotMissions(self._naming)

    def mission(self, robot: int) -> str:
        """The mission name of a robot number."""
        return f"{self.prefix}robot{robot}"

    def _naming(self, robot: int) -> tuple[str, str]:
        return self.mission(robot), f"robot{robot}"

    def read(self, lines: Iterable[str], source: str = "") -> None:
        """Read one file's text (its header line first).

        Raises:
            MapImportError: a wrong header or a malformed row (the message names the line).
        """
        rows = csv.reader(lines)
        header = next(rows, None)
        if header is None or [h.strip() for h in header] != HEADER:
            raise MapImportError(f"expected the header {','.join(HEADER)}", source=source, line=1)
        for row in rows:
            if not row:
                continue
            self._row(row, source, rows.line_num)

    def _row(self, row: list[str], source: str, line: int) -> None:
        if len(row) != len(HEADER):
            raise MapImportError(
                f"expected {len(HEADER)} columns, found {len(row)}", source=source, line=line
            )
        try:
            a, i, b, j = (int(v) for v in row[:4])
            qx, qy, qz, qw, tx, ty, tz, kappa, tau = (float(v) for v in row[4:13])
        except ValueError as exc:
            raise MapImportError(f"not a number: {exc}", source=source, line=line) from None
        if min(a, i, b, j) < 0 or not math.isfinite(qx + qy + qz + qw + tx + ty + tz + kappa + tau):
            raise MapImportError("ids must be natural and values finite", source=source, line=line)
        if abs(math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw) - 1.0) > 1e-3:
            raise MapImportError("quaternion qx..qw is not a unit", source=source, line=line)
        self.rows += 1
        if self.progress is not None and self.rows % 10_000 == 0:
            self.progress(self.rows, 0)
        # an inter-robot edge read from the other robot's file already is skipped
        self._missions.add_edge(
            (a, i, b, j),
            (a, i),
            (b, j),
            (tx, ty, tz, qx, qy, qz, qw),
            isotropic_information(tau, kappa),
            Origin(self.rows),  # its place among the rows read: the import order
        )

    def graphs(self) -> list[MissionGraph]:
        """One mission per robot, by robot number, with chained trajectories."""
        if self.progress is not None:
            self.progress(self.rows, self.rows)
        return self._missions.graphs()


def read_kimera(
    folder: str | Path, prefix: str = "", progress: Progress | None = None
) -> list[MissionGraph]:
    """Read every `robot*/measurements.csv` under `folder`: one mission per robot.

    Raises:
        MapImportError: no such files, or one is malformed.
    """
    folder = Path(folder)
    files = sorted(folder.glob(f"robot*/{FILE_NAME}"), key=lambda p: _robot_number(p.parent.name))
    if not files:
        raise MapImportError(f"no robot*/{FILE_NAME} files", source=str(folder))
    reader = KimeraReader(prefix, progress)
    for path in files:
        with path.open(encoding="utf-8", newline="") as lines:
            reader.read(lines, str(path))
    return reader.graphs()


def _robot_number(name: str) -> int:
    digits = name.removeprefix("robot")
    return int(digits) if digits.isdigit() else -1
