"""Axis-aligned boxes in the map frame (DESIGN §7), pure: the closed box every
spatial query, registration and plot speaks of, with its checks and geometry.
Boxes are closed (``min <= max``; a point is a valid box) and two boxes overlap
when they share at least one point, touching faces included; a malformed box
(min > max, NaN, infinite) raises `InvalidBBox`.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, fields

from mapapi.core.errors import InvalidBBox

Point = tuple[float, float, float]
"""A point ``(x, y, z)`` in the map frame, in metres."""


@dataclass(frozen=True, slots=True)
class BBox:
    """An axis-aligned, closed 3-D box in the map frame (metres).

    ``min == max`` on an axis is allowed (a flat box, or a point). Coordinates
    are stored as floats; ``-0.0`` is stored as ``0.0`` so equal boxes have
    equal keys and fingerprints.

    Raises:
        InvalidBBox: a coordinate is not a finite number, or a min exceeds its max.
    """

    xmin: float
    ymin: float
    zmin: float
    xmax: float
    ymax: float
    zmax: float

    def __post_init__(self) -> None:
        for f in fields(self):
            raw = getattr(self, f.name)
            try:
                value = float(raw) + 0.0  # + 0.0 turns -0.0 into 0.0
            except (TypeError, ValueError) as exc:
                raise InvalidBBox(f"bbox {f.name} is not a number: {raw!r}") from exc
            if not math.isfinite(value):
                raise InvalidBBox(f"bbox {f.name} must be finite, got {raw!r}")
            object.__setattr__(self, f.name, value)
        for axis, lo, hi in zip("xyz", self.mins, self.maxs, strict=True):
            if lo > hi:
                raise InvalidBBox(
                    f"bbox {axis}min {lo!r} > {axis}max {hi!r}; give the minimum corner first"
                )

    @classmethod
    def from_tuple(cls, values: Sequence[float]) -> BBox:
        """The box ``(xmin, ymin, zmin, xmax, ymax, zmax)``, the order the CLI and
        `mapapi.lookup.extent` use.

        Raises:
            InvalidBBox: not six values, or invalid as for the constructor.
        """
        if len(values) != 6:
            raise InvalidBBox(
                f"a bbox needs 6 values (xmin ymin zmin xmax ymax zmax), got {len(values)}"
            )
        return cls(*values)

    @classmethod
    def around(cls, point: Point) -> BBox:
        """The zero-size box holding only `point`."""
        x, y, z = point
        return cls(x, y, z, x, y, z)

    @classmethod
    def enclosing(cls, boxes: Iterable[BBox]) -> BBox:
        """The smallest box holding every box of `boxes` (e.g. a chunk's items).

        Raises:
            ValueError: `boxes` is empty.
        """
        it = iter(boxes)
        try:
            result = next(it)
        except StopIteration:
            raise ValueError("enclosing() needs at least one box") from None
        for box in it:
            result = result.union(box)
        return result

    def as_tuple(self) -> tuple[float, float, float, float, float, float]:
        """``(xmin, ymin, zmin, xmax, ymax, zmax)``."""
        return (self.xmin, self.ymin, self.zmin, self.xmax, self.ymax, self.zmax)

    @property
    def mins(self) -> Point:
        """The minimum corner ``(xmin, ymin, zmin)``."""
        return (self.xmin, self.ymin, self.zmin)

    @property
    def maxs(self) -> Point:
        """The maximum corner ``(xmax, ymax, zmax)``."""
        return (self.xmax, self.ymax, self.zmax)

    def overlaps(self, other: BBox) -> bool:
        """True when the two closed boxes share at least one point (touching counts)."""
        return (
            self.xmin <= other.xmax
            and other.xmin <= self.xmax
            and self.ymin <= other.ymax
            and other.ymin <= self.ymax
            and self.zmin <= other.zmax
            and other.zmin <= self.zmax
        )

    def intersection(self, other: BBox) -> BBox | None:
        """The common part of the two boxes, or None when they do not overlap.

        Clamping a query to an index's bounds is ``box.intersection(bounds)``.
        """
        if not self.overlaps(other):
            return None
        return BBox(
            max(self.xmin, other.xmin),
            max(self.ymin, other.ymin),
            max(self.zmin, other.zmin),
            min(self.xmax, other.xmax),
            min(self.ymax, other.ymax),
            min(self.zmax, other.zmax),
        )

    def union(self, other: BBox) -> BBox:
        """The smallest box holding both boxes."""
        return BBox(
            min(self.xmin, other.xmin),
            min(self.ymin, other.ymin),
            min(self.zmin, other.zmin),
            max(self.xmax, other.xmax),
            max(self.ymax, other.ymax),
            max(self.zmax, other.zmax),
        )

    def contains(self, point: Point) -> bool:
        """True when `point` lies in the closed box."""
        x, y, z = point
        return (
            self.xmin <= x <= self.xmax
            and self.ymin <= y <= self.ymax
            and self.zmin <= z <= self.zmax
        )

    def clamp_point(self, point: Point) -> Point:
        """The point of the box nearest to `point` (per-axis clamp)."""
        return (
            min(max(point[0], self.xmin), self.xmax),
            min(max(point[1], self.ymin), self.ymax),
            min(max(point[2], self.zmin), self.zmax),
        )


# Default index geometry (DESIGN §7, `mapctl init`). Map frames are metric and
# centred near where the swarm started. A 2,048 m x 2,048 m square covers a campus,
# a port or a mine site as well as any building or garage; +-128 m of height covers
# multi-storey buildings, tunnels and hills. 32 x 32 x 1 cells give 64 m x 64 m
# columns: a robot's local query (tens of metres) touches 1-4 cells and a whole
# mission registers in a few dozen, and 1,024 keys spread evenly over a swarm of
# up to ~100 peers. There is no split in z: ground robots' missions span all their
# floors, and a split near ground level would make most boxes straddle it. Powers of
# two keep every cell edge exact in binary floating point.
