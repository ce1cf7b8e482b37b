"""Spatial index invariants (DESIGN §7): the fast cell arithmetic of
`mapapi.lookup.spatial` equals brute force over every cell, on random grids, boxes and
points; and a query of the index over a real Chord ring returns exactly what a
brute-force filter over every registered box returns."""

from __future__ import annotations

import asyncio
import itertools
import random
import threading
from collections.abc import Awaitable, Callable, Iterator
from typing import Any, TypeVar

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mapapi.core.ids import ChunkId, PeerId
from mapapi.lookup.dht.chord import ChordNode
from mapapi.lookup.spatial import BBox, Point, SpatialGrid
from mapapi.lookup.spatial_index import SpatialIndex, SpatialRef
from mapbench.ring import still_ring

T = TypeVar("T")

EXAMPLES = settings(max_examples=100, deadline=None)


@st.composite
def grids(draw: st.DrawFn) -> SpatialGrid:
    """A grid with random bounds (any offset, 1 cm to 10 km per axis) and 1-6 cells per axis."""
    lows = [draw(st.floats(-1e4, 1e4)) for _ in range(3)]
    extents = [draw(st.floats(1e-2, 1e4)) for _ in range(3)]
    cells = tuple(draw(st.integers(1, 6)) for _ in range(3))
    bounds = BBox(*lows, *(lo + ext for lo, ext in zip(lows, extents, strict=True)))
    return SpatialGrid(bounds, cells)  # type: ignore[arg-type]


def coordinate(grid: SpatialGrid, axis: int) -> st.SearchStrategy[float]:
    """Values around one axis of the grid, often exactly on a cell edge or a bound."""
    lo, hi = grid.bounds.mins[axis], grid.bounds.maxs[axis]
    span = hi - lo
    along = [[0, 0, 0] for _ in range(grid.cells[axis])]
    for i, coords in enumerate(along):
        coords[axis] = i
    edges = [grid.cell_box(grid.cell_index(*c)).mins[axis] for c in along] + [hi]
    return st.one_of(
        st.sampled_from(edges),
        st.floats(lo, hi),
        st.floats(lo - span, hi + span),
    )


def points(grid: SpatialGrid) -> st.SearchStrategy[Point]:
    return st.tuples(coordinate(grid, 0), coordinate(grid, 1), coordinate(grid, 2))


@st.composite
def boxes(draw: st.DrawFn, grid: SpatialGrid) -> BBox:
    """A box whose corners each may lie inside, on the edge of, or outside the bounds."""
    a, b = draw(points(grid)), draw(points(grid))
    return BBox(*map(min, a, b), *map(max, a, b))


def in_half_open_cell(grid: SpatialGrid, index: int, point: Point) -> bool:
    """Brute-force ownership: [lo, hi) per axis, the upper bound in the last cell."""
    cell = grid.cell_box(index)
    return all(
        lo <= v < hi or v == hi == top
        for lo, hi, v, top in zip(cell.mins, cell.maxs, point, grid.bounds.maxs, strict=True)
    )


class TestCellsOverlapping:
    @EXAMPLES
    @given(data=st.data(), grid=grids())
    def test_equals_brute_force_over_all_cells(
        self, data: st.DataObject, grid: SpatialGrid
    ) -> None:
        box = data.draw(boxes(grid))
        clamped = grid.clamp(box)
        expected = (
            []
            if clamped is None
            else [i for i in range(grid.cell_count) if grid.cell_box(i).overlaps(clamped)]
        )
        assert grid.cells_overlapping(box) == expected

    @EXAMPLES
    @given(data=st.data(), grid=grids())
    def test_overlapping_boxes_share_a_cell(self, data: st.DataObject, grid: SpatialGrid) -> None:
        # the index's correctness: a query finds every registered box it overlaps
        registered, query = data.draw(boxes(grid)), data.draw(boxes(grid))
        common = registered.intersection(query)
        if common is not None and grid.clamp(common) is not None:
            assert set(grid.cells_overlapping(registered)) & set(grid.cells_overlapping(query))


class TestCellOf:
    @EXAMPLES
    @given(data=st.data(), grid=grids())
    def test_every_point_is_in_exactly_one_cell(
        self, data: st.DataObject, grid: SpatialGrid
    ) -> None:
        point = grid.bounds.clamp_point(data.draw(points(grid)))
        index = grid.cell_of(point)
        assert grid.cell_box(index).contains(point)
        owners = [i for i in range(grid.cell_count) if in_half_open_cell(grid, i, point)]
        assert owners == [index]
        assert index in grid.cells_overlapping(BBox.around(point))

    @EXAMPLES
    @given(data=st.data(), grid=grids())
    def test_clamping_picks_the_cell_of_the_nearest_point(
        self, data: st.DataObject, grid: SpatialGrid
    ) -> None:
        point = data.draw(points(grid))
        assert grid.cell_of(point, clamp=True) == grid.cell_of(grid.bounds.clamp_point(point))


class TestCellKeys:
    @settings(max_examples=30, deadline=None)
    @given(grid=grids(), name=st.text(min_size=1, max_size=12))
    def test_keys_are_distinct_160_bit_and_stable(self, grid: SpatialGrid, name: str) -> None:
        keys = [grid.cell_key(i, name) for i in range(grid.cell_count)]
        assert len(set(keys)) == len(keys)
        assert all(0 <= k < 1 << 160 for k in keys)
        again = SpatialGrid.from_config(grid.to_config())
        assert again.config_fingerprint() == grid.config_fingerprint()
        assert [again.cell_key(i, name) for i in range(grid.cell_count)] == keys


# -- the index over a real ring ------------------------------------------------------

RING_GRID = SpatialGrid(BBox(-100, -100, -10, 100, 100, 10), (8, 8, 2))
TABLES = ("rooms", "clouds")

Run = Callable[[Awaitable[T]], T]


@pytest.fixture(scope="module")
def ring() -> Iterator[tuple[Run[Any], list[ChordNode]]]:
    """A still ring of 4 nodes on an event loop in a thread of its own, so that
    hypothesis (synchronous) can drive it example after example."""
    loop = asyncio.new_event_loop()
    thread = threading.Thread(target=loop.run_forever, name="ring loop", daemon=True)
    thread.start()

    def run(coro: Awaitable[T]) -> T:
        return asyncio.run_coroutine_threadsafe(coro, loop).result(timeout=60)  # type: ignore[arg-type]

    nodes_cm = still_ring(4, random.Random(11))
    nodes = run(nodes_cm.__aenter__())
    try:
        yield run, nodes
    finally:
        run(nodes_cm.__aexit__(None, None, None))
        loop.call_soon_threadsafe(loop.stop)
        thread.join(timeout=10)
        loop.close()


@st.composite
def refs(draw: st.DrawFn) -> SpatialRef:
    rng = random.Random(draw(st.integers(0, 2**32)))
    return SpatialRef(
        ChunkId(f"{rng.getrandbits(128):032x}"),
        draw(st.sampled_from(TABLES)),
        draw(boxes(RING_GRID)),
        holders=((PeerId(f"{rng.getrandbits(128):032x}"), "tcp://127.0.0.1:1"),),
    )


_index_names = (f"example-{n}" for n in itertools.count())


class TestIndexOverTheRing:
    @settings(max_examples=40, deadline=None)
    @given(
        registered=st.lists(refs(), max_size=10, unique_by=lambda r: r.chunk),
        query=boxes(RING_GRID),
        table=st.sampled_from((None, *TABLES)),
        exact_at_owner=st.booleans(),
        data=st.data(),
    )
    def test_query_equals_a_brute_force_filter(
        self,
        ring: tuple[Run[Any], list[ChordNode]],
        registered: list[SpatialRef],
        query: BBox,
        table: str | None,
        exact_at_owner: bool,
        data: st.DataObject,
    ) -> None:
        run, nodes = ring
        name = next(_index_names)  # a fresh index: no entry of an earlier example
        indexes = [SpatialIndex(node, RING_GRID, name) for node in nodes]
        for ref in registered:
            run(data.draw(st.sampled_from(indexes)).register(ref, ttl=600))
        asker = data.draw(st.sampled_from(indexes))

        found = run(asker.query(query, table, exact_at_owner=exact_at_owner))

        inside = RING_GRID.clamp(query) is not None
        expected = [
            r
            for r in registered
            if inside
            and RING_GRID.clamp(r.bbox) is not None
            and r.bbox.overlaps(query)
            and table in (None, r.table)
        ]
        assert found == sorted(expected, key=lambda r: r.chunk)
