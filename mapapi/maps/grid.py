"""Occupancy grids from laser scans, written as a nav2 `map_server` map (issue 17 §4).

A grid is a raster of square cells over a box of the x/y plane (`GridSpec`).
Each ray of a scan, from the pose that took it to its return, is cast into it
(`OccupancyCounts.add_rays`): the cell of the return counts a *hit*, every
other cell the ray crosses a *pass*. A cell's occupancy is the share of the
rays reaching it that ended there, hits / (hits + passes) (the counting
model, as GMapping's cells keep it): above `OCCUPIED_P` it is
occupied, below `FREE_P` free, else, or never reached, unknown.

Casting is vectorised with numpy (a Python loop per ray, Bresenham's, took
about 50 s for the 2.4M rays of the whole Intel log, extrapolated from 20,000;
this takes 6-9 s: docs/benchmarks.md). A ray enters a new
cell each time it crosses a line between columns or rows, so the cells it
crosses are its start cell and the cell after each such crossing, which are
found without walking the ray: the k-th column line it crosses is a known x,
where its y follows from the line's equation (and the same for rows). The
crossings of a batch of rays are made at once with `np.repeat` and counted
with `np.bincount`: exactly the cells the ray touches, in 1.27 samples per
cell of length on average (|cos| + |sin|), none twice.

`write_nav2` writes the map as nav2's `map_server` reads it: a binary PGM
(P5) with 0 for occupied, 254 free and 205 unknown, its first row the top
(largest y), and the YAML beside it. Pure: numpy only.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from mapapi.core.errors import UsageError

XY = npt.NDArray[np.float64]  # shape (n, 2)

MAX_SIDE = 8192
"""The most cells a grid may have along a side (8192 x 8192 is 64 Mi cells, two
counters of 4 bytes each: 512 MiB while casting)."""

OCCUPIED_P, FREE_P = 0.65, 0.25
"""A cell is occupied above, free below this share of hits (nav2's defaults)."""

OCCUPIED, FREE, UNKNOWN = 0, 254, 205
"""The pixel values of nav2's trinary maps (what `map_saver` writes)."""

YAML_FREE_THRESH = 0.196
"""The `free_thresh` written: nav2 reads a pixel as occupancy 1 - value / 255, so
205 (unknown) reads 0.196, which `free_thresh: 0.25` would make free; a
threshold of 0.196 keeps it unknown (as ROS 1's map_saver and, since
navigation2 PR #5278, nav2's write for trinary maps)."""

_RAYS_AT_ONCE = 1 << 18  # rays cast at once: ~30 MB of per-ray temporaries
_BATCH_SAMPLES = 1 << 20  # crossings of those made at once: ~100 MB of temporaries


@dataclass(frozen=True, slots=True)
class GridSpec:
    """Where a grid lies: its lower-left corner, cell side and size.

    Attributes:
        x0: x of the left edge of column 0, metres.
        y0: y of the bottom edge of the last row (the image's bottom), metres.
        resolution: a cell's side, metres.
        width: columns.
        height: rows.
    """

    x0: float
    y0: float
    resolution: float
    width: int
    height: int

    @property
    def cells(self) -> int:
        """How many cells it has."""
        return self.width * self.height


def grid_spec(xmin: float, ymin: float, xmax: float, ymax: float, resolution: float) -> GridSpec:
    """The grid of `resolution` covering the box, its corner at (xmin, ymin).

    Raises:
        UsageError: a resolution that is not positive, an empty box, or a grid
            wider or taller than `MAX_SIDE` cells (the message names its size
            and the coarsest resolution that fits).
    """
    if not resolution > 0:
        raise UsageError(f"the resolution must be positive, not {resolution}")
    if not (xmax > xmin and ymax > ymin):
        raise UsageError(f"the box {xmin} {ymin} {xmax} {ymax} is empty in x or y")
    width = math.ceil((xmax - xmin) / resolution)
    height = math.ceil((ymax - ymin) / resolution)
    if max(width, height) > MAX_SIDE:
        finest = max(xmax - xmin, ymax - ymin) / MAX_SIDE
        raise UsageError(
            f"a grid of {width} x {height} cells at {resolution} m is larger than "
            f"{MAX_SIDE} x {MAX_SIDE}; choose a smaller box or a resolution of at least "
            f"{math.ceil(finest * 1000) / 1000} m"
        )
    return GridSpec(xmin, ymin, resolution, width, height)


class OccupancyCounts:
    """Hits and passes per cell of one grid, as rays are cast into it."""

    def __init__(self, spec: GridSpec) -> None:
        self.spec = spec
        self.hits = np.zeros(spec.cells, dtype=np.int32)
        self.passes = np.zeros(spec.cells, dtype=np.int32)

    def add_rays(self, origins: XY, ends: XY) -> None:
        """Cast a ray from each origin to its end (metres): its end cell is hit,
        the cells before it passed. Parts outside the grid are left out."""
        for lo in range(0, len(ends), _RAYS_AT_ONCE):  # bounds the per-ray temporaries
            self._add(origins[lo : lo + _RAYS_AT_ONCE], ends[lo : lo + _RAYS_AT_ONCE])

    def _add(self, origins: XY, ends: XY) -> None:
        spec = self.spec
        corner = np.array([spec.x0, spec.y0])
        start = (np.asarray(origins, np.float64) - corner) / spec.resolution  # in cells
        stop = (np.asarray(ends, np.float64) - corner) / spec.resolution
        keep = _crosses_grid(start, stop, spec)
        start, stop = start[keep], stop[keep]
        first, last = np.floor(start).astype(np.int64), np.floor(stop).astype(np.int64)
        end_cells = self._flat(last[:, 0], last[:, 1])
        _count(self.hits, end_cells[end_cells >= 0])
        start_cells = self._flat(first[:, 0], first[:, 1])
        _count(self.passes, start_cells[(start_cells >= 0) & (start_cells != end_cells)])
        crossings = np.abs(last - first)  # cell boundaries crossed in x, in y
        for lo, hi in _batches(crossings.sum(axis=1)):
            for axis in (0, 1):
                cells, ray = self._entered(start[lo:hi], stop[lo:hi], axis, crossings[lo:hi, axis])
                passed = (cells >= 0) & (cells != end_cells[lo:hi][ray])
                _count(self.passes, cells[passed])

    def _entered(
        self, start: XY, stop: XY, axis: int, count: npt.NDArray[np.int64]
    ) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
        """The cell each ray enters at each boundary it crosses between columns
        (`axis` 0) or rows (1), flat, and the ray of each."""
        ray = np.repeat(np.arange(len(count)), count)
        k = np.arange(len(ray)) - (np.cumsum(count) - count)[ray]
        delta = stop - start
        ahead = delta[:, axis] > 0
        step = np.where(ahead, 1, -1)
        base = np.floor(start[:, axis])
        line = base + ahead  # the first line crossed, then one a step further each time
        with np.errstate(divide="ignore", invalid="ignore"):  # rays crossing no line
            slope = delta[:, 1 - axis] / delta[:, axis]
        offset = start[:, 1 - axis] - start[:, axis] * slope  # across = offset + slope * line
        boundary = line[ray] + step[ray] * k
        along = boundary.astype(np.int64) - ~ahead[ray]  # the column (row) entered
        across = np.floor(offset[ray] + slope[ray] * boundary).astype(np.int64)
        cols, rows = (along, across) if axis == 0 else (across, along)
        return self._flat(cols, rows), ray

    def _flat(self, col: npt.NDArray[np.int64], y: npt.NDArray[np.int64]) -> npt.NDArray[np.int64]:
        """The flat index (row 0 the top) of the cell in column `col`, `y` cells
        up from the bottom; -1 outside the grid."""
        spec = self.spec
        row = spec.height - 1 - y
        inside = (col >= 0) & (col < spec.width) & (row >= 0) & (row < spec.height)
        return np.where(inside, row * spec.width + col, -1)

    def image(self) -> npt.NDArray[np.uint8]:
        """The trinary picture (height x width, row 0 the top): `OCCUPIED`,
        `FREE` or `UNKNOWN` per cell."""
        seen = self.hits + self.passes
        share = np.divide(self.hits, seen, out=np.full(seen.shape, np.nan), where=seen > 0)
        pixels = np.full(seen.shape, UNKNOWN, dtype=np.uint8)
        pixels[share > OCCUPIED_P] = OCCUPIED
        pixels[share < FREE_P] = FREE
        return pixels.reshape(self.spec.height, self.spec.width)


def _crosses_grid(start: XY, stop: XY, spec: GridSpec) -> npt.NDArray[np.bool_]:
    """The rays whose box overlaps the grid (in cells): the others cast nothing."""
    lo, hi = np.minimum(start, stop), np.maximum(start, stop)
    return (hi[:, 0] >= 0) & (lo[:, 0] < spec.width) & (hi[:, 1] >= 0) & (lo[:, 1] < spec.height)


def _batches(samples: npt.NDArray[np.int64]) -> list[tuple[int, int]]:
    """Runs of rays of about `_BATCH_SAMPLES` samples (crossings) together: the
    rays whose first sample falls in the same stretch of `_BATCH_SAMPLES`."""
    group = (np.cumsum(samples) - samples) // _BATCH_SAMPLES
    edges = [0, *(np.flatnonzero(np.diff(group)) + 1).tolist(), len(samples)]
    return [(a, b) for a, b in itertools.pairwise(edges) if b > a]


def _count(counts: npt.NDArray[np.int32], cells: npt.NDArray[np.int64]) -> None:
    """Add one to `counts` at each of `cells` (repeats add up)."""
    if len(cells) == 0:
        return
    lo, hi = int(cells.min()), int(cells.max()) + 1
    # a batch's rays come from nearby scans, so its cells span a small part of a large
    # grid: counting over that span is a pass over it; sorting (np.unique) costs some
    # 50 times more per cell, so it only pays when the span is much larger than the batch
    if hi - lo <= 8 * len(cells):
        counts[lo:hi] += np.bincount(cells - lo, minlength=hi - lo).astype(np.int32)
    else:
        found, times = np.unique(cells, return_counts=True)
        counts[found] += times.astype(np.int32)


def write_nav2(pixels: npt.NDArray[np.uint8], spec: GridSpec, yaml_path: Path) -> Path:
    """Write `pixels` (from `OccupancyCounts.image`) as nav2's map: a PGM named
    after `yaml_path` beside it, and the YAML; returns the PGM's path."""
    image = yaml_path.with_suffix(".pgm")
    header = (
        f"P5\n# mapapi occupancy grid, {spec.resolution} m/cell\n{spec.width} {spec.height}\n255\n"
    )
    with image.open("wb") as out:
        out.write(header.encode("ascii"))
        out.write(np.ascontiguousarray(pixels, dtype=np.uint8).tobytes())
    yaml_path.write_text(
        f"image: {image.name}\n"
        "mode: trinary\n"
        f"resolution: {spec.resolution!r}\n"
        f"origin: [{spec.x0!r}, {spec.y0!r}, 0.0]\n"
        "negate: 0\n"
        f"occupied_thresh: {OCCUPIED_P}\n"
        f"free_thresh: {YAML_FREE_THRESH}\n",
        encoding="ascii",
    )
    return image
