"""Scan matching: a laser mission's trajectory corrected by its own scans.

A CARMEN log's poses are raw wheel odometry, which drifts by metres and tens of
degrees over a building: an occupancy grid cast from them smears every wall
(the whole Intel log gives a fan of rays, not a floor plan). Each scan is laid
on the map made of the scans before it, and its pose taken where it fits best,
so the trajectory follows the walls rather than the wheels.

How, in the manner of a correlative scan matcher (Olson 2009), pure numpy:

- The map is a likelihood field: each cell holds how near it lies to a point
  of an earlier scan (a Gaussian of the distance, `SIGMA`), kept as the highest
  value any point gave, so adding a scan costs a few thousand cell writes.
- A scan is matched when the robot has moved `KEY_DISTANCE` or turned
  `KEY_TURN` since the last matched scan (a keyframe). Its pose is searched
  around the odometry's prediction from that keyframe: first on a coarse
  lattice of positions and headings, half its points and the nearest cell,
  then on a fine lattice around the best, every point and the field
  interpolated between cells. The best pose is the one whose points land on
  the highest sum of likelihood. Only keyframes are added to the map.
- A scan between keyframes takes the odometry's motion from the keyframe
  before it: over 20 cm the odometry's drift is millimetres.

This corrects the drift from one scan to the next, not the error a long loop
accumulates (that would need loop closures and a pose-graph solve): on the
Intel log the map stays one consistent floor plan, with corridors slightly
bent.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from mapapi.maps.carmen import Pose2, relative_se2
from mapapi.maps.laser import Correction, LaserMission
from mapapi.maps.plane import Placement
from mapapi.maps.se3 import from_se2, yaw

Array = npt.NDArray[np.float64]

RESOLUTION = 0.05
"""The field's cell side, metres: a SICK's range noise is about 1 cm, its beams
1 degree apart, so 5 cm keeps a wall one or two cells thick."""

SIGMA = 0.05
"""How far a point's likelihood reaches, metres: the width of a wall in the field."""

KEY_DISTANCE = 0.2
KEY_TURN = math.radians(10.0)
"""A scan is matched once the odometry has moved this far or turned this much
since the last matched one."""

MIN_POINTS = 30
"""A scan with fewer returns (an open space, a blinded laser) is not matched:
too few points fit anywhere."""

# (step, steps either side) of the coarse and the fine search, in metres and radians:
# the coarse one spans +-0.2 m and +-7.5 degrees, more than odometry drifts in a keyframe.
_COARSE = (0.05, 4, math.radians(1.5), 5)
_FINE = (0.0125, 3, math.radians(0.25), 4)
_GROW = 20.0  # metres added on each side when a scan falls off the field

Progress = Callable[[int, int], None]


@dataclass(frozen=True)
class Matched:
    """A trajectory corrected by its scans.

    Attributes:
        poses: (n, 3) x, y, heading of every pose, in the odometry's frame
            (the first pose unchanged).
        keyframes: how many scans were matched.
        largest: the largest distance, metres, between a corrected pose and its odometry.
    """

    poses: Array
    keyframes: int
    largest: float


class LikelihoodField:
    """How near each cell of the plane lies to an earlier scan's point (see the
    module docstring); it grows as the scans reach further."""

    def __init__(self, centre: Sequence[float], half: float) -> None:
        self.origin = np.asarray(centre, dtype=np.float64) - half
        side = math.ceil(2 * half / RESOLUTION) + 1
        self.cells = np.zeros((side, side), dtype=np.float32)
        reach = math.ceil(3 * SIGMA / RESOLUTION)
        offsets = np.arange(-reach, reach + 1)
        di, dj = np.meshgrid(offsets, offsets, indexing="ij")
        self._di, self._dj = di.ravel(), dj.ravel()
        distance2 = (self._di**2 + self._dj**2) * RESOLUTION**2
        self._kernel = np.exp(-distance2 / (2 * SIGMA**2)).astype(np.float32)
        self._reach = reach

    def add(self, points: Array) -> None:
        """Mark the (m, 2) `points` (metres) in the field."""
        self._fit(points)
        cell = np.floor((points - self.origin) / RESOLUTION).astype(np.int64)
        rows = (cell[:, 0, None] + self._di).ravel()
        cols = (cell[:, 1, None] + self._dj).ravel()
        values = np.broadcast_to(self._kernel, (len(cell), self._kernel.size)).ravel()
        np.maximum.at(self.cells, (rows, cols), values)

    def score(self, local: Array, poses: Array, *, smooth: bool) -> Array:
        """For each of the (k, 3) `poses`, the sum of the field under the (m, 2)
        `local` points placed there: interpolated between cells if `smooth`,
        else the cell each point falls in. A point off the field scores 0."""
        cos, sin = np.cos(poses[:, 2:3]), np.sin(poses[:, 2:3])
        x = poses[:, 0:1] + cos * local[:, 0] - sin * local[:, 1]
        y = poses[:, 1:2] + sin * local[:, 0] + cos * local[:, 1]
        fx = (x - self.origin[0]) / RESOLUTION
        fy = (y - self.origin[1]) / RESOLUTION
        side = self.cells.shape[0]
        if not smooth:
            i, j = np.floor(fx).astype(np.int64), np.floor(fy).astype(np.int64)
            inside = (i >= 0) & (i < side) & (j >= 0) & (j < side)
            values = self.cells[np.clip(i, 0, side - 1), np.clip(j, 0, side - 1)]
            return np.asarray(np.where(inside, values, 0.0).sum(axis=1))
        fx, fy = fx - 0.5, fy - 0.5  # a cell's value sits at its centre
        i, j = np.floor(fx).astype(np.int64), np.floor(fy).astype(np.int64)
        ax, ay = fx - i, fy - j
        inside = (i >= 0) & (i < side - 1) & (j >= 0) & (j < side - 1)
        i, j = np.clip(i, 0, side - 2), np.clip(j, 0, side - 2)
        c = self.cells
        values = (c[i, j] * (1 - ax) + c[i + 1, j] * ax) * (1 - ay)
        values += (c[i, j + 1] * (1 - ax) + c[i + 1, j + 1] * ax) * ay
        return np.asarray(np.where(inside, values, 0.0).sum(axis=1))

    def _fit(self, points: Array) -> None:
        """Grow the field so that every point's kernel lies on it."""
        margin = (self._reach + 1) * RESOLUTION
        low = points.min(axis=0) - margin - self.origin
        high = points.max(axis=0) + margin - self.origin - self.cells.shape[0] * RESOLUTION
        short_before = max(0, math.ceil(-low.min() / RESOLUTION))  # cells missing, each end
        short_after = max(0, math.ceil(high.max() / RESOLUTION))
        if not short_before and not short_after:
            return
        pad = round(_GROW / RESOLUTION)  # room for the next scans too: padding copies the field
        before = short_before + pad if short_before else 0
        after = short_after + pad if short_after else 0
        self.cells = np.pad(self.cells, ((before, after), (before, after)))
        self.origin = self.origin - before * RESOLUTION


def match_scans(
    odometry: Array, scans: Sequence[Array | None], progress: Progress | None = None
) -> Matched:
    """Correct the trajectory `odometry` ((n, 3) x, y, heading) by its scans.

    Args:
        scans: per pose, its scan's points ((m, 2), metres) in the robot's frame
            at that pose, or None for a pose without a scan.
        progress: called with (poses done, poses) now and then.
    """
    count = len(odometry)
    poses = odometry.astype(np.float64).copy()
    field: LikelihoodField | None = None
    key = -1  # the last keyframe's index
    matched = 0
    for n in range(count):
        if progress is not None and n % 500 == 0:
            progress(n, count)
        scan = scans[n]
        if key >= 0:
            step = relative_se2(_planar(odometry[key]), _planar(odometry[n]))
            poses[n] = compose(poses[key], step)
            near = math.hypot(step[0], step[1]) < KEY_DISTANCE and abs(step[2]) < KEY_TURN
            if near or scan is None or len(scan) < MIN_POINTS or field is None:
                continue
            poses[n] = _search(field, scan, poses[n])
            matched += 1
        if scan is None or len(scan) < MIN_POINTS:
            continue
        if field is None:
            field = LikelihoodField(poses[n][:2], half=50.0)
        field.add(place(scan, poses[n]))
        key = n
    if progress is not None:
        progress(count, count)
    largest = float(np.max(np.hypot(*(poses[:, :2] - odometry[:, :2]).T))) if count else 0.0
    return Matched(poses, matched, largest)


def _search(field: LikelihoodField, scan: Array, guess: Array) -> Array:
    """The pose near `guess` where `scan` fits the field best: coarse, then fine."""
    best = _best(field, scan[::2], guess, _COARSE, smooth=False)
    return _best(field, scan, best, _FINE, smooth=True)


def _best(
    field: LikelihoodField,
    scan: Array,
    guess: Array,
    lattice: tuple[float, int, float, int],
    *,
    smooth: bool,
) -> Array:
    step, steps, turn, turns = lattice
    shifts = np.arange(-steps, steps + 1) * step
    angles = np.arange(-turns, turns + 1) * turn
    dx, dy, da = np.meshgrid(shifts, shifts, angles, indexing="ij")
    candidates = guess + np.stack([dx.ravel(), dy.ravel(), da.ravel()], axis=1)
    scores = field.score(scan, candidates, smooth=smooth)
    return np.asarray(candidates[int(np.argmax(scores))])


def place(local: Array, pose: Array) -> Array:
    """The (m, 2) points `local`, given in the frame of `pose`, in the pose's frame."""
    return Placement(float(pose[0]), float(pose[1]), float(pose[2])).apply(local)


def seen_from(points: Array, pose: Array) -> Array:
    """The (m, 2) `points` in the frame of `pose` (the inverse of `place`)."""
    cos, sin = math.cos(pose[2]), math.sin(pose[2])
    dx, dy = points[:, 0] - pose[0], points[:, 1] - pose[1]
    return np.stack([cos * dx + sin * dy, -sin * dx + cos * dy], axis=1)


def _planar(row: Array) -> Pose2:
    return (float(row[0]), float(row[1]), float(row[2]))


def compose(a: Array, b: Pose2) -> Array:
    """The planar pose `b`, given in the frame of `a`, in `a`'s frame."""
    ((x, y),) = place(np.array([b[:2]]), a)
    return np.array([x, y, a[2] + b[2]])


def match_mission(laser: LaserMission, progress: Progress | None = None) -> Correction:
    """Correct `laser`'s poses by its scans, in place: each vertex takes its
    matched pose and each scan's points move with it. Its odometry edges stay:
    they are what the wheels measured."""
    keys = sorted(laser.vertices)
    odometry = np.array([(p[0], p[1], yaw(p)) for p in (laser.vertices[k] for k in keys)])
    scans = [
        seen_from(laser.scans[k][:, :2].astype(np.float64), odometry[n])
        if k in laser.scans
        else None
        for n, k in enumerate(keys)
    ]
    matched = match_scans(odometry, scans, progress)
    for n, k in enumerate(keys):
        laser.vertices[k] = from_se2(*(float(v) for v in matched.poses[n]))
        scan = scans[n]
        if scan is not None:
            points = np.zeros((len(scan), 3), dtype=np.float32)
            points[:, :2] = place(scan, matched.poses[n])
            laser.scans[k] = points
    laser.correction = Correction(matched.keyframes, round(matched.largest, 3))
    return laser.correction
