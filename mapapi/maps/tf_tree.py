"""A TF tree as a bag records it (`/tf`, `/tf_static`): where one frame lies in
another at a time, composed along the tree (issue 17: "TF gives frames").

Each frame has one parent (as in ROS's tf2: TF is a tree). A link is static
(it holds at every time) or dynamic: a series of stamped transforms, looked up
between two of them by interpolation, linear in translation and spherical
(slerp) in rotation, as tf2 does.

Outside a dynamic link's series, a lookup holds its first or last transform
for up to `TOLERANCE` seconds and is refused further on (`TfOutOfRange`): it
never extrapolates a motion. tf2 refuses any stamp past the series; we accept
a few tens of milliseconds because a sensor's message is often stamped a
little after the last odometry transform (a 50 Hz odometry is 20 ms apart),
and at a robot's 1 m/s, holding a transform 50 ms moves a point 5 cm, about a
lidar's own range noise; further on, the error grows with speed, so the scan
is better refused than placed wrong.

Pure: no file, no numpy; poses are `mapapi.maps.se3` 7-tuples.
"""

from __future__ import annotations

import logging
import math
from bisect import bisect_right
from dataclasses import dataclass, field

from mapapi.maps.se3 import IDENTITY, Pose, compose, inverse

log = logging.getLogger(__name__)

TOLERANCE = 0.05
"""Seconds a lookup may fall outside a dynamic link's transforms (see the module
docstring)."""


class TfError(ValueError):
    """A TF lookup that cannot be answered."""


class NoTfPath(TfError):
    """Two frames are not joined by the tree: no transform relates them at any time.

    Attributes:
        target, source: the frames of the lookup.
    """

    def __init__(self, target: str, source: str, roots: tuple[str, str]) -> None:
        self.target, self.source = target, source
        super().__init__(
            f"no TF path from {source} to {target}: {source} is in the tree of "
            f"{roots[0]}, {target} in that of {roots[1]}"
        )


class TfOutOfRange(TfError):
    """A dynamic link has no transform near enough the time asked for.

    Attributes:
        parent, child: the link's frames.
        stamp: the time asked for, seconds.
        first, last: the times of the link's first and last transforms.
    """

    def __init__(
        self, parent: str, child: str, stamp: float, known: tuple[float, float], tolerance: float
    ) -> None:
        self.parent, self.child, self.stamp = parent, child, stamp
        self.first, self.last = known
        super().__init__(
            f"TF {parent} -> {child} is known from {self.first:.3f} to {self.last:.3f} s, "
            f"not at {stamp:.3f} s (more than {tolerance} s outside)"
        )


@dataclass
class _Link:
    """A frame's transform from its parent: static, or stamped transforms."""

    parent: str
    static: Pose | None = None
    stamps: list[float] = field(default_factory=list)
    poses: list[Pose] = field(default_factory=list)
    ordered: bool = True

    def add(self, stamp: float, pose: Pose) -> None:
        if self.stamps and stamp < self.stamps[-1]:
            self.ordered = False  # sorted once, at the next lookup
        self.stamps.append(stamp)
        self.poses.append(pose)

    def at(self, child: str, stamp: float, tolerance: float) -> Pose:
        """The child's pose in the parent at `stamp` (see the module docstring)."""
        if self.static is not None:
            return self.static
        if not self.ordered:
            pairs = sorted(zip(self.stamps, self.poses, strict=True), key=lambda p: p[0])
            self.stamps, self.poses = [s for s, _ in pairs], [p for _, p in pairs]
            self.ordered = True
        stamps = self.stamps
        after = bisect_right(stamps, stamp)
        if after == 0 or after == len(stamps):
            near = 0 if after == 0 else len(stamps) - 1
            if abs(stamp - stamps[near]) > tolerance:
                known = (stamps[0], stamps[-1])
                raise TfOutOfRange(self.parent, child, stamp, known, tolerance)
            return self.poses[near]
        start, stop = stamps[after - 1], stamps[after]
        return interpolate(
            self.poses[after - 1], self.poses[after], (stamp - start) / (stop - start)
        )


class TfTree:
    """The frames a bag's TF messages join, and where each lies in another at a time.

    Args:
        tolerance: seconds a lookup may fall outside a dynamic link's transforms.
    """

    def __init__(self, tolerance: float = TOLERANCE) -> None:
        self.tolerance = tolerance
        self._links: dict[str, _Link] = {}

    def add(self, parent: str, child: str, stamp: float, pose: Pose, *, static: bool) -> None:
        """Record `child`'s pose in `parent` at `stamp` (any time, when `static`).

        A frame keeps the first parent given: a transform naming another parent
        is ignored (and logged), since a TF frame has one parent.
        """
        link = self._links.setdefault(child, _Link(parent))
        if link.parent != parent:
            log.warning("TF %s -> %s ignored: %s has parent %s", parent, child, child, link.parent)
            return
        if static:
            link.static = pose  # a republished static transform replaces the last
        else:
            link.add(stamp, pose)

    def frames(self) -> set[str]:
        """Every frame a transform named, as parent or child."""
        return set(self._links) | {link.parent for link in self._links.values()}

    def parent(self, frame: str) -> str | None:
        """The frame's parent, None for a root or a frame TF never named."""
        link = self._links.get(frame)
        return None if link is None else link.parent

    def lookup(self, target: str, source: str, stamp: float) -> Pose:
        """The pose of frame `source` in frame `target` at `stamp`: it maps a point
        given in `source` to `target` (`compose(pose, (p, identity))`).

        Raises:
            NoTfPath: the frames are in different trees.
            TfOutOfRange: a dynamic link of the path has no transform near `stamp`.
        """
        up_source, up_target = self._chain(source), self._chain(target)
        common = next((f for f in up_source if f in up_target), None)
        if common is None:
            raise NoTfPath(target, source, (up_source[-1], up_target[-1]))
        in_common = self._to_ancestor(up_source, common, stamp)
        target_in_common = self._to_ancestor(up_target, common, stamp)
        return compose(inverse(target_in_common), in_common)

    def _chain(self, frame: str) -> list[str]:
        """The frame and its ancestors, the root last (a loop, which a TF tree
        should not have, ends the chain where it closes)."""
        chain = [frame]
        seen = {frame}
        while (up := self.parent(chain[-1])) is not None and up not in seen:
            chain.append(up)
            seen.add(up)
        return chain

    def _to_ancestor(self, chain: list[str], ancestor: str, stamp: float) -> Pose:
        """The pose of `chain[0]` in `ancestor`, one of the chain's frames."""
        pose = IDENTITY
        for child in chain[: chain.index(ancestor)]:
            pose = compose(self._links[child].at(child, stamp, self.tolerance), pose)
        return pose


def interpolate(a: Pose, b: Pose, share: float) -> Pose:
    """The pose `share` (0 to 1) of the way from `a` to `b`: linear in
    translation, slerp in rotation along the shorter arc."""
    position = tuple(u + share * (v - u) for u, v in zip(a[:3], b[:3], strict=True))
    p, q = a[3:], list(b[3:])
    dot = sum(u * v for u, v in zip(p, q, strict=True))
    if dot < 0:  # q and -q are one rotation: take the shorter way round
        q, dot = [-v for v in q], -dot
    if dot > 0.9995:  # nearly one rotation: sin(angle) ~ 0, and linear is exact enough
        wa, wb = 1.0 - share, share
    else:
        angle = math.acos(dot)
        wa = math.sin((1.0 - share) * angle) / math.sin(angle)
        wb = math.sin(share * angle) / math.sin(angle)
    mixed = [wa * u + wb * v for u, v in zip(p, q, strict=True)]
    norm = math.sqrt(sum(v * v for v in mixed))
    x, y, z = position
    qx, qy, qz, qw = (v / norm for v in mixed)
    return (x, y, z, qx, qy, qz, qw)
