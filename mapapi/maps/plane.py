"""Rigid motions of the plane, for occupancy grids (issue 17 §4): where a
grid's cells lie when its origin is turned (a `nav_msgs/OccupancyGrid` whose
origin has a yaw) or its mission is placed in the world frame (`frames`).

A grid is 2D, so only a place that keeps the plane level moves it: a turn
about z and a shift in x and y (`planar_placement`); a place that tilts the
plane by more than `TILT_LIMIT` would squeeze the grid's cells into other
shapes, and is refused. Pure: numpy only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mapapi.core.errors import UsageError
from mapapi.maps.alignment import pose_matrix
from mapapi.maps.grid import XY
from mapapi.maps.se3 import Pose

TILT_LIMIT = 1e-3
"""Radians (0.057 degrees) a place may tilt the plane by: the cells it moves
then shrink by less than a millionth (1 - cos), far below a cell."""


@dataclass(frozen=True, slots=True)
class Placement:
    """A rigid motion of the plane: a turn by `yaw` radians about the origin,
    then a shift by (`x`, `y`) metres."""

    x: float = 0.0
    y: float = 0.0
    yaw: float = 0.0

    def apply(self, points: XY) -> XY:
        """The points (n x 2, metres) moved."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        px, py = points[:, 0], points[:, 1]
        # the shift added last, to the turned offset: unturned, x + offset exactly
        return np.stack([self.x + (c * px - s * py), self.y + (s * px + c * py)], axis=1)

    def then(self, outer: Placement) -> Placement:
        """This motion followed by `outer`."""
        ((x, y),) = outer.apply(np.array([[self.x, self.y]]))
        return Placement(float(x), float(y), self.yaw + outer.yaw)


IDENTITY = Placement()


def planar_placement(pose: Pose, what: str) -> Placement:
    """The motion of the plane that the place `pose` (x, y, z, qx, qy, qz, qw)
    makes: its x, y and its turn about z.

    Raises:
        UsageError: the pose tilts the plane by more than `TILT_LIMIT`; the
            message names `what` is placed so.
    """
    move = pose_matrix(pose)
    tilt = math.acos(min(1.0, max(-1.0, float(move[2, 2]))))  # the angle z turns by
    if tilt > TILT_LIMIT:
        raise UsageError(
            f"{what} tilts the plane by {math.degrees(tilt):.3f} degrees; an occupancy grid "
            f"is 2D and is placed by a turn about z only (at most "
            f"{math.degrees(TILT_LIMIT):.3f} degrees of tilt): write it in its own frame "
            "(--frame mission)"
        )
    return Placement(float(move[0, 3]), float(move[1, 3]), math.atan2(move[1, 0], move[0, 0]))
