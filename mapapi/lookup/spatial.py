"""Pure grid arithmetic for the spatial index (DESIGN §7).

A spatial index covers a fixed bounding space split into a regular grid of
``nx * ny * nz`` cells. Each cell has a deterministic 160-bit Chord key; the
DHT layer (`mapapi.lookup`) stores ``(ref, box)`` entries under the keys of
every cell a registered box overlaps. This module only does the arithmetic:
boxes, clamping, which cells a box touches, and the keys. It imports no
asyncio, zmq or protobuf.

Conventions, chosen to design out the C++ original's bugs (research notes §3.5); the
boxes themselves are `lookup/bbox.py`:

- **One cell numbering**, x fastest: ``index = ix + nx * (iy + ny * iz)``.
  The original iterated cells x-fastest in one place and z-fastest in another.
- **Boxes are closed** (``min <= max``, a point is a valid box) and two boxes
  overlap when they share at least one point, touching faces included.
- **A point belongs to exactly one cell**: cell ``i`` along an axis holds
  ``[edge[i], edge[i+1])``, except that the last cell also holds the upper
  bound, so a value equal to ``max`` maps to the last cell.
- **Queries never crash on the bounds**: a box partly outside is clamped, a box
  fully outside overlaps no cell. Only malformed boxes (min > max, NaN, inf)
  raise `InvalidBBox`.
- Cell edges are computed once per axis and shared by `cell_of`,
  `cells_overlapping` and `cell_box`, so the three can never disagree by a
  floating-point rounding at a boundary.
"""

from __future__ import annotations

import hashlib
import math
from bisect import bisect_left, bisect_right
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from itertools import pairwise
from typing import Any

from mapapi.core.errors import InvalidBBox, QueryError, UsageError
from mapapi.core.ids import ring_key
from mapapi.lookup.bbox import BBox, Point

Cells = tuple[int, int, int]
"""Cell counts ``(nx, ny, nz)`` of a grid."""

MAX_CELLS = 1 << 20
"""Upper limit on ``nx * ny * nz``: every cell is a DHT key, so a grid beyond a
million cells is a configuration mistake, not a finer index."""

_KEY_DOMAIN = "mapapi/spatial-cell/v1"


DEFAULT_BOUNDS = BBox(-1024.0, -1024.0, -128.0, 1024.0, 1024.0, 128.0)
DEFAULT_CELLS: Cells = (32, 32, 1)


def _axis_edges(lo: float, hi: float, n: int) -> tuple[float, ...]:
    """``n + 1`` increasing edges from `lo` to exactly `hi`."""
    width = hi - lo
    edges = [lo + width * k / n for k in range(n)]
    edges.append(hi)
    return tuple(edges)


@dataclass(frozen=True)
class SpatialGrid:
    """A regular grid over fixed bounds: the cell arithmetic of one spatial index.

    Args:
        bounds: the space the index covers; every axis needs a positive extent.
        cells: cell counts ``(nx, ny, nz)``, each >= 1, at most `MAX_CELLS` in all.

    Raises:
        InvalidBBox: the bounds are flat on some axis.
        UsageError: a cell count is not a positive integer, the total exceeds
            `MAX_CELLS`, or the cells are too small for floating point.
    """

    bounds: BBox = DEFAULT_BOUNDS
    cells: Cells = DEFAULT_CELLS
    _edges: tuple[tuple[float, ...], ...] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        counts = tuple(self.cells)
        if len(counts) != 3 or not all(
            isinstance(n, int) and not isinstance(n, bool) and n >= 1 for n in counts
        ):
            raise UsageError(f"cell counts must be three integers >= 1, got {self.cells!r}")
        if math.prod(counts) > MAX_CELLS:
            raise UsageError(
                f"{math.prod(counts)} cells exceed the limit of {MAX_CELLS}; use fewer cells"
            )
        object.__setattr__(self, "cells", counts)
        edges = []
        for axis, lo, hi, n in zip("xyz", self.bounds.mins, self.bounds.maxs, counts, strict=True):
            if not lo < hi:
                raise InvalidBBox(
                    f"index bounds need a positive extent on every axis; {axis} is [{lo}, {hi}]"
                )
            axis_edges = _axis_edges(lo, hi, n)
            if any(a >= b for a, b in pairwise(axis_edges)):
                raise UsageError(f"{n} cells along {axis} are too small for [{lo}, {hi}]")
            edges.append(axis_edges)
        object.__setattr__(self, "_edges", tuple(edges))

    # -- configuration -------------------------------------------------------------

    @classmethod
    def from_config(cls, config: Mapping[str, Any]) -> SpatialGrid:
        """The grid of a config table ``{"bounds": [6 floats], "cells": [3 ints]}``
        (the shape kept in ``.mapapi/config.toml``); missing keys take the defaults.

        Raises:
            InvalidBBox, UsageError: as for the constructor.
        """
        bounds = config.get("bounds")
        cells = config.get("cells")
        if cells is not None and (isinstance(cells, str) or not isinstance(cells, Sequence)):
            raise UsageError(f"cell counts must be a list of three integers, got {cells!r}")
        return cls(
            DEFAULT_BOUNDS if bounds is None else BBox.from_tuple(bounds),
            DEFAULT_CELLS if cells is None else tuple(cells),  # type: ignore[arg-type]
        )

    def to_config(self) -> dict[str, list[float] | list[int]]:
        """The config table `from_config` reads back to an equal grid."""
        return {"bounds": list(self.bounds.as_tuple()), "cells": list(self.cells)}

    def _canonical(self) -> str:
        # repr(float) round-trips exactly; the numbering is part of the config, so
        # a peer with another linearization can never match.
        bounds = ",".join(repr(v) for v in self.bounds.as_tuple())
        nx, ny, nz = self.cells
        return f"bounds={bounds};cells={nx},{ny},{nz};numbering=x-fastest"

    def config_fingerprint(self) -> str:
        """A 40-hex-digit digest of bounds, cell counts and cell numbering.

        Peers exchange it to refuse a peer whose index geometry differs
        (DESIGN §7: the grid must agree across the swarm).
        """
        return hashlib.sha1(self._canonical().encode()).hexdigest()

    def describe(self) -> str:
        """A one-line human description, for error messages and `mapctl` output."""
        b = self.bounds
        nx, ny, nz = self.cells
        return (
            f"bounds x[{b.xmin:g}, {b.xmax:g}] y[{b.ymin:g}, {b.ymax:g}] "
            f"z[{b.zmin:g}, {b.zmax:g}], cells {nx}x{ny}x{nz}"
        )

    # -- cells ---------------------------------------------------------------------

    @property
    def cell_count(self) -> int:
        """``nx * ny * nz``."""
        return math.prod(self.cells)

    def cell_index(self, ix: int, iy: int, iz: int) -> int:
        """The number of the cell at grid coordinates ``(ix, iy, iz)`` (x fastest).

        Raises:
            ValueError: a coordinate is outside the grid.
        """
        nx, ny, nz = self.cells
        if not (0 <= ix < nx and 0 <= iy < ny and 0 <= iz < nz):
            raise ValueError(f"cell ({ix}, {iy}, {iz}) is outside a {nx}x{ny}x{nz} grid")
        return ix + nx * (iy + ny * iz)

    def cell_coords(self, index: int) -> tuple[int, int, int]:
        """The grid coordinates ``(ix, iy, iz)`` of cell `index`.

        Raises:
            ValueError: `index` is not a cell of this grid.
        """
        self._check_index(index)
        nx, ny, _ = self.cells
        rest, ix = divmod(index, nx)
        iz, iy = divmod(rest, ny)
        return ix, iy, iz

    def cell_box(self, index: int) -> BBox:
        """The closed box of cell `index`.

        Raises:
            ValueError: `index` is not a cell of this grid.
        """
        ix, iy, iz = self.cell_coords(index)
        ex, ey, ez = self._edges
        return BBox(ex[ix], ey[iy], ez[iz], ex[ix + 1], ey[iy + 1], ez[iz + 1])

    def cell_of(self, point: Point, *, clamp: bool = False) -> int:
        """The one cell holding `point`.

        Along each axis cell ``i`` holds ``[edge[i], edge[i+1])``; the upper bound
        belongs to the last cell. The returned cell's `cell_box` contains `point`.

        Args:
            point: ``(x, y, z)``.
            clamp: map a point outside the bounds to the nearest cell instead of
                raising.

        Raises:
            InvalidBBox: a coordinate is NaN or infinite.
            QueryError: `point` is outside the bounds and `clamp` is false.
        """
        if len(point) != 3 or not all(math.isfinite(v) for v in point):
            raise InvalidBBox(f"a point needs three finite coordinates, got {point!r}")
        if not self.bounds.contains(point):
            if not clamp:
                raise QueryError(
                    f"point {point!r} is outside the spatial index ({self.describe()}); "
                    "clamp it, or query a box instead"
                )
            point = self.bounds.clamp_point(point)
        coords = [
            min(bisect_right(edges, v) - 1, n - 1)
            for edges, v, n in zip(self._edges, point, self.cells, strict=True)
        ]
        return self.cell_index(*coords)

    def clamp(self, box: BBox) -> BBox | None:
        """`box` cut to the bounds, or None when it lies fully outside them."""
        return box.intersection(self.bounds)

    def cells_overlapping(self, box: BBox) -> list[int]:
        """The cells whose closed box overlaps `box`, ascending (x fastest).

        A box partly outside the bounds is clamped first; a box fully outside
        overlaps no cell. A box face lying exactly on a cell edge also touches
        the neighbouring cell (boxes are closed), which only adds a candidate:
        exact filtering happens at the cell owner (DESIGN §7).
        """
        clamped = self.clamp(box)
        if clamped is None:
            return []
        ranges = []
        for edges, lo, hi, n in zip(
            self._edges, clamped.mins, clamped.maxs, self.cells, strict=True
        ):
            # cell i overlaps [lo, hi] iff edges[i] <= hi and edges[i + 1] >= lo
            first = max(bisect_left(edges, lo) - 1, 0)
            last = min(bisect_right(edges, hi) - 1, n - 1)
            ranges.append(range(first, last + 1))
        rx, ry, rz = ranges
        nx, ny, _ = self.cells
        return [ix + nx * (iy + ny * iz) for iz in rz for iy in ry for ix in rx]

    def cell_key(self, index: int, index_name: str) -> int:
        """The 160-bit Chord key of cell `index` of the index named `index_name`.

        SHA-1 of a stable string holding the index name, the bounds, the cell
        counts, the numbering and the cell number, so two indexes, or two peers
        with different grids, never share a key silently.

        Raises:
            ValueError: `index` is not a cell of this grid, or the name is empty.
        """
        self._check_index(index)
        if not index_name:
            raise ValueError("a spatial index needs a non-empty name")
        # length-prefixed name: no name can imitate another name plus config
        return ring_key(
            f"{_KEY_DOMAIN}|{len(index_name)}:{index_name}|{self._canonical()}|cell={index}"
        )

    def _check_index(self, index: int) -> None:
        if isinstance(index, bool) or not isinstance(index, int):
            raise ValueError(f"a cell number is an int, got {index!r}")
        if not 0 <= index < self.cell_count:
            raise ValueError(f"cell {index} is outside a grid of {self.cell_count} cells")
