"""Which way a top-down picture looks: the map's up direction and the picture's
two axes, so that every picture is a view from above in metres, whatever axis
convention the map was recorded in.

Shared by the matplotlib plots (`plot.py`) and the open3d renderer (`render3d.py`).

Up is a signed axis of the map's frame. Given as `--up` (x, y, z, -x, -y, -z),
or found from the poses: a robot drives forward, so the body axis its motion
mostly follows tells the convention its poses use. Along body x it is a robot
body (REP 103: z up); along body z a camera (optical frame: y down). That body
up, carried into the map by every pose's rotation, points to the map's up (the
tunnels set, recorded by cameras, has its up along -y). Without poses to tell
(point clouds alone, or no clear forward axis), the axis along which the map is
thinnest is taken, positive.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from mapapi.core.errors import UsageError
from mapapi.lookup.spatial import BBox

AXES = "xyz"
UP_CHOICES = ("auto", "x", "y", "z", "-x", "-y", "-z")

# Body forward axis -> the body's up in that convention (x: REP 103; z: camera optical).
_BODY_UP = {0: np.array([0.0, 0.0, 1.0]), 2: np.array([0.0, -1.0, 0.0])}
_CLEAR = 0.5  # a mean unit direction shorter than this says nothing


@dataclass(frozen=True)
class Up:
    """The map's up direction: an axis of its frame and which way along it."""

    axis: int
    sign: int = 1

    @property
    def name(self) -> str:
        """`z`, `-y`...: as `--up` takes it."""
        return ("-" if self.sign < 0 else "") + AXES[self.axis]

    def height(self, points: np.ndarray) -> np.ndarray:
        """How high each of the (n, 3) `points` lies along up."""
        return np.asarray(points[:, self.axis] * self.sign)


Z_UP = Up(2)  # a map with z up: the view the REP 103 convention gives


def choose_up(boxes: Sequence[BBox], up: str = "auto", poses: Sequence[np.ndarray] = ()) -> Up:
    """The map's up: `up` if it names a signed axis, else the one the poses
    tell (see the module's docstring), else the axis along which the boxes'
    union is thinnest.

    Args:
        poses: per trajectory, its (n, 7) array of poses (x y z qx qy qz qw) in order.

    Raises:
        UsageError: `up` is not one of `UP_CHOICES`.
    """
    if up not in UP_CHOICES:
        raise UsageError(f"--up must be one of {', '.join(UP_CHOICES)}, not {up!r}")
    if up != "auto":
        return Up(AXES.index(up[-1]), -1 if up.startswith("-") else 1)
    told = up_from_poses(poses)
    if told is not None:
        return told
    if not boxes:
        return Z_UP
    union = BBox.enclosing(boxes)
    extent = [hi - lo for lo, hi in zip(union.mins, union.maxs, strict=True)]
    return Up(int(np.argmin(extent)))


def up_from_poses(poses: Sequence[np.ndarray]) -> Up | None:
    """The up the trajectories' own motion tells, or None where it is not clear."""
    ups = [u for u in (_trajectory_up(p) for p in poses) if u is not None]
    if not ups:
        return None
    mean = np.mean(ups, axis=0)
    axis = int(np.argmax(np.abs(mean)))
    if abs(mean[axis]) < _CLEAR:
        return None
    return Up(axis, 1 if mean[axis] > 0 else -1)


def _trajectory_up(poses: np.ndarray) -> np.ndarray | None:
    """One trajectory's mean up direction in the map, from its body convention."""
    if len(poses) < 2:
        return None
    rotations = poses[:-1, 3:7]
    steps = np.diff(poses[:, :3], axis=0)
    lengths = np.linalg.norm(steps, axis=1)
    moving = lengths > 1e-6
    if not moving.any():
        return None
    # Each step seen from the pose it leaves: the inverse rotation is the conjugate.
    body = _rotate(rotations[moving] * [-1, -1, -1, 1], steps[moving] / lengths[moving, None])
    forward = body.mean(axis=0)
    axis = int(np.argmax(np.abs(forward)))
    if forward[axis] < _CLEAR or axis not in _BODY_UP:
        return None
    return np.asarray(
        _rotate(rotations, np.broadcast_to(_BODY_UP[axis], (len(rotations), 3))).mean(axis=0)
    )


def _rotate(quaternions: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """Each of `vectors` turned by its unit quaternion (x, y, z, w)."""
    q, w = quaternions[:, :3], quaternions[:, 3:4]
    twice = 2.0 * np.cross(q, vectors)
    return np.asarray(vectors + w * twice + np.cross(q, twice))


def plane_axes(up: Up) -> tuple[int, int]:
    """The picture's two axes (its x, then its y) looking down on the map from
    above along `up`: right-handed about up, so the view is never mirrored."""
    u, v = {0: (1, 2), 1: (2, 0), 2: (0, 1)}[up.axis]
    return (u, v) if up.sign > 0 else (v, u)
