"""Which way a top-down picture looks: the axis to look down and the picture's two axes.

Shared by the matplotlib plots (`plot.py`) and the open3d renderer (`render3d.py`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from mapapi.core.errors import UsageError
from mapapi.lookup.spatial import BBox

AXES = "xyz"


def choose_up(boxes: Sequence[BBox], up: str = "auto") -> int:
    """The index of the axis to look down: `up` if it names one, else the axis
    along which the boxes' union is thinnest.

    Raises:
        UsageError: `up` is not auto, x, y or z.
    """
    if up in AXES:
        return AXES.index(up)
    if up != "auto":
        raise UsageError(f"--up must be auto, x, y or z, not {up!r}")
    if not boxes:
        return 2
    union = BBox.enclosing(boxes)
    extent = [hi - lo for lo, hi in zip(union.mins, union.maxs, strict=True)]
    return int(np.argmin(extent))


def plane_axes(up: int) -> tuple[int, int]:
    """The two axes of the picture when looking down axis `up` (right-handed)."""
    return {0: (1, 2), 1: (2, 0), 2: (0, 1)}[up]
