"""Spatial grid arithmetic (mapapi.lookup.spatial, DESIGN §7)."""

from __future__ import annotations

import math

import pytest

from mapapi.core.errors import InvalidBBox, MapError, QueryError, UsageError
from mapapi.lookup.spatial import (
    DEFAULT_BOUNDS,
    DEFAULT_CELLS,
    MAX_CELLS,
    BBox,
    SpatialGrid,
)

CUBE = BBox(0, 0, 0, 2, 2, 2)
GOLDEN_KEY = 0xE8546F2FF67FA3747E09EA05BC8D3A8CA12452E7  # default grid, cell 0, "missions"


def grid222() -> SpatialGrid:
    """The C++ original's SpatialIndexTest setup: [0, 2]^3 split 2x2x2."""
    return SpatialGrid(CUBE, (2, 2, 2))


class TestInvalidBBoxError:
    def test_is_a_query_error_and_a_value_error(self) -> None:
        assert issubclass(InvalidBBox, QueryError)
        assert issubclass(InvalidBBox, ValueError)
        assert issubclass(QueryError, MapError)

    def test_has_its_own_code_and_usage_exit_status(self) -> None:
        assert QueryError.code != InvalidBBox.code
        assert QueryError.exit_code == InvalidBBox.exit_code == 2
        assert not InvalidBBox.retriable


class TestBBoxValidation:
    def test_stores_floats(self) -> None:
        box = BBox(0, 1, 2, 3, 4, 5)
        assert box.as_tuple() == (0.0, 1.0, 2.0, 3.0, 4.0, 5.0)
        assert all(isinstance(v, float) for v in box.as_tuple())

    def test_a_point_is_a_valid_box(self) -> None:
        assert BBox.around((1.0, 2.0, 3.0)) == BBox(1, 2, 3, 1, 2, 3)

    @pytest.mark.parametrize("axis", range(3))
    def test_min_above_max_is_rejected(self, axis: int) -> None:
        values = [0.0, 0.0, 0.0, 1.0, 1.0, 1.0]
        values[axis] = 2.0
        with pytest.raises(InvalidBBox, match=f"{'xyz'[axis]}min"):
            BBox.from_tuple(values)

    @pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
    def test_non_finite_is_rejected(self, bad: float) -> None:
        with pytest.raises(InvalidBBox, match="finite"):
            BBox(0, 0, 0, 1, bad, 1)

    def test_non_number_is_rejected(self) -> None:
        with pytest.raises(InvalidBBox, match="not a number"):
            BBox(0, 0, 0, 1, 1, "north")  # type: ignore[arg-type]

    def test_invalid_bbox_is_catchable_as_value_error(self) -> None:
        with pytest.raises(ValueError, match="xmin"):
            BBox(1, 0, 0, 0, 1, 1)

    def test_from_tuple_needs_six_values(self) -> None:
        with pytest.raises(InvalidBBox, match="6 values"):
            BBox.from_tuple([0, 0, 0, 1, 1])

    def test_negative_zero_is_normalised(self) -> None:
        box = BBox(-0.0, 0, 0, 0, 0, 0)
        assert math.copysign(1.0, box.xmin) == 1.0
        assert box == BBox(0, 0, 0, 0, 0, 0)

    def test_is_immutable_and_hashable(self) -> None:
        box = BBox(0, 0, 0, 1, 1, 1)
        with pytest.raises(AttributeError):
            box.xmin = 5  # type: ignore[misc]
        assert {box, BBox(0, 0, 0, 1, 1, 1)} == {box}


class TestBBoxGeometry:
    def test_overlap_of_nested_boxes(self) -> None:
        assert CUBE.overlaps(BBox(0.5, 0.5, 0.5, 1, 1, 1))
        assert BBox(0.5, 0.5, 0.5, 1, 1, 1).overlaps(CUBE)

    def test_touching_faces_overlap(self) -> None:
        assert CUBE.overlaps(BBox(2, 0, 0, 3, 2, 2))

    def test_touching_corners_overlap(self) -> None:
        assert CUBE.overlaps(BBox(2, 2, 2, 3, 3, 3))

    @pytest.mark.parametrize("axis", range(3))
    def test_separated_on_one_axis_do_not_overlap(self, axis: int) -> None:
        values = [0.5, 0.5, 0.5, 1.0, 1.0, 1.0]
        values[axis], values[axis + 3] = 2.5, 3.0
        other = BBox.from_tuple(values)
        assert not CUBE.overlaps(other)
        assert not other.overlaps(CUBE)

    def test_intersection(self) -> None:
        assert CUBE.intersection(BBox(1, -1, 1.5, 3, 1, 5)) == BBox(1, 0, 1.5, 2, 1, 2)

    def test_intersection_of_touching_boxes_is_flat(self) -> None:
        assert CUBE.intersection(BBox(2, 0, 0, 3, 2, 2)) == BBox(2, 0, 0, 2, 2, 2)

    def test_intersection_of_disjoint_boxes_is_none(self) -> None:
        assert CUBE.intersection(BBox(3, 3, 3, 4, 4, 4)) is None

    def test_union_and_enclosing(self) -> None:
        a, b = BBox(0, 0, 0, 1, 1, 1), BBox(-1, 2, 0.5, 0, 3, 0.5)
        assert a.union(b) == BBox(-1, 0, 0, 1, 3, 1)
        assert BBox.enclosing([a, b, a]) == a.union(b)
        assert BBox.enclosing([a]) == a

    def test_enclosing_nothing_is_an_error(self) -> None:
        with pytest.raises(ValueError, match="at least one"):
            BBox.enclosing([])

    def test_contains_is_closed(self) -> None:
        assert CUBE.contains((0, 0, 0))
        assert CUBE.contains((2, 2, 2))
        assert CUBE.contains((1, 1.5, 0.5))
        assert not CUBE.contains((2.0001, 1, 1))

    def test_clamp_point(self) -> None:
        assert CUBE.clamp_point((-1, 1, 5)) == (0, 1, 2)
        assert CUBE.clamp_point((1, 1, 1)) == (1, 1, 1)


class TestGridConfig:
    def test_defaults(self) -> None:
        grid = SpatialGrid()
        assert grid.bounds == DEFAULT_BOUNDS
        assert grid.cells == DEFAULT_CELLS
        assert grid.cell_count == 32 * 32
        # 64 m columns with edges exact in binary floating point
        assert grid.cell_box(0) == BBox(-1024, -1024, -128, -960, -960, 128)
        assert grid.cell_box(grid.cell_count - 1) == BBox(960, 960, -128, 1024, 1024, 128)

    @pytest.mark.parametrize("axis", range(3))
    def test_flat_bounds_are_rejected(self, axis: int) -> None:
        values = [0.0, 0.0, 0.0, 1.0, 1.0, 1.0]
        values[axis + 3] = 0.0
        with pytest.raises(InvalidBBox, match="positive extent"):
            SpatialGrid(BBox.from_tuple(values), (1, 1, 1))

    @pytest.mark.parametrize(
        "cells", [(0, 1, 1), (1, -2, 1), (1, 1, 1.5), (True, 1, 1), (1, 1), (1, 1, 1, 1)]
    )
    def test_bad_cell_counts_are_rejected(self, cells: tuple[int, int, int]) -> None:
        with pytest.raises(UsageError, match="three integers"):
            SpatialGrid(CUBE, cells)

    def test_too_many_cells_are_rejected(self) -> None:
        with pytest.raises(UsageError, match="exceed"):
            SpatialGrid(CUBE, (MAX_CELLS, 2, 1))

    def test_cells_below_float_resolution_are_rejected(self) -> None:
        with pytest.raises(UsageError, match="too small"):
            SpatialGrid(BBox(1e9, 0, 0, 1e9 + 1e-6, 1, 1), (1000, 1, 1))

    def test_config_round_trip(self) -> None:
        grid = SpatialGrid(BBox(-5, -6, -1, 5, 6, 3.5), (4, 3, 2))
        config = grid.to_config()
        assert config == {"bounds": [-5.0, -6.0, -1.0, 5.0, 6.0, 3.5], "cells": [4, 3, 2]}
        assert SpatialGrid.from_config(config) == grid

    def test_config_defaults_for_missing_keys(self) -> None:
        assert SpatialGrid.from_config({}) == SpatialGrid()
        assert SpatialGrid.from_config({"cells": [2, 2, 2]}).bounds == DEFAULT_BOUNDS

    def test_config_rejects_bad_values(self) -> None:
        with pytest.raises(UsageError):
            SpatialGrid.from_config({"cells": "2x2x2"})
        with pytest.raises(InvalidBBox):
            SpatialGrid.from_config({"bounds": [0, 0, 0, 1, 1]})

    def test_describe(self) -> None:
        assert grid222().describe() == "bounds x[0, 2] y[0, 2] z[0, 2], cells 2x2x2"

    def test_fingerprint_is_stable_and_sensitive(self) -> None:
        fp = grid222().config_fingerprint()
        assert len(fp) == 40
        assert int(fp, 16) >= 0
        assert fp == SpatialGrid(BBox(-0.0, 0, 0, 2, 2, 2), (2, 2, 2)).config_fingerprint()
        assert fp != SpatialGrid(CUBE, (2, 2, 1)).config_fingerprint()
        assert fp != SpatialGrid(CUBE, (4, 1, 2)).config_fingerprint()
        assert fp != SpatialGrid(BBox(0, 0, 0, 2, 2, 2.5), (2, 2, 2)).config_fingerprint()

    def test_grids_compare_by_config(self) -> None:
        assert grid222() == grid222()
        assert hash(grid222()) == hash(grid222())
        assert grid222() != SpatialGrid(CUBE, (2, 2, 1))


class TestNumbering:
    def test_x_varies_fastest(self) -> None:
        grid = SpatialGrid(BBox(0, 0, 0, 4, 3, 2), (4, 3, 2))
        assert grid.cell_index(0, 0, 0) == 0
        assert grid.cell_index(1, 0, 0) == 1
        assert grid.cell_index(0, 1, 0) == 4
        assert grid.cell_index(0, 0, 1) == 12
        assert grid.cell_index(3, 2, 1) == 23

    def test_coords_round_trip(self) -> None:
        grid = SpatialGrid(BBox(0, 0, 0, 4, 3, 2), (4, 3, 2))
        for index in range(grid.cell_count):
            assert grid.cell_index(*grid.cell_coords(index)) == index

    def test_cell_boxes_of_the_originals_test_in_one_order(self) -> None:
        # The original listed these z-fastest in one place and x-fastest in another.
        boxes = [grid222().cell_box(i) for i in range(8)]
        expected = [
            BBox(x, y, z, x + 1, y + 1, z + 1) for z in (0, 1) for y in (0, 1) for x in (0, 1)
        ]
        assert boxes == expected

    @pytest.mark.parametrize("index", [-1, 8, 100])
    def test_out_of_range_cell_is_rejected(self, index: int) -> None:
        with pytest.raises(ValueError, match="outside a grid of 8"):
            grid222().cell_box(index)

    def test_non_int_cell_is_rejected(self) -> None:
        with pytest.raises(ValueError, match="is an int"):
            grid222().cell_coords(1.0)  # type: ignore[arg-type]

    def test_out_of_range_coords_are_rejected(self) -> None:
        with pytest.raises(ValueError, match="outside a 2x2x2"):
            grid222().cell_index(2, 0, 0)


class TestCellOf:
    def test_interior_point(self) -> None:
        assert grid222().cell_of((1.5, 0.5, 0.5)) == 1
        assert grid222().cell_of((0.5, 1.5, 1.5)) == 6

    def test_point_on_an_inner_edge_goes_to_the_upper_cell(self) -> None:
        assert grid222().cell_of((1, 1, 1)) == 7

    def test_min_corner_is_cell_zero_and_max_corner_the_last_cell(self) -> None:
        assert grid222().cell_of((0, 0, 0)) == 0
        assert grid222().cell_of((2, 2, 2)) == 7
        assert grid222().cell_of((2, 0, 0)) == 1

    def test_outside_point_raises_a_query_error(self) -> None:
        with pytest.raises(QueryError, match="outside the spatial index"):
            grid222().cell_of((2.5, 1, 1))

    def test_outside_point_can_be_clamped(self) -> None:
        assert grid222().cell_of((2.5, -1, 1.5), clamp=True) == 5

    @pytest.mark.parametrize("bad", [math.nan, math.inf])
    def test_non_finite_point_is_invalid(self, bad: float) -> None:
        with pytest.raises(InvalidBBox, match="finite"):
            grid222().cell_of((bad, 1, 1), clamp=True)

    def test_single_cell_grid(self) -> None:
        grid = SpatialGrid(CUBE, (1, 1, 1))
        assert {grid.cell_of(p) for p in [(0, 0, 0), (1, 1, 1), (2, 2, 2)]} == {0}


class TestCellsOverlapping:
    def test_box_inside_one_cell(self) -> None:
        assert grid222().cells_overlapping(BBox(0.1, 0.1, 0.1, 0.9, 0.9, 0.9)) == [0]

    def test_box_across_cells_is_sorted_in_numbering_order(self) -> None:
        assert grid222().cells_overlapping(BBox(0.5, 0.5, 0.1, 1.5, 1.5, 0.9)) == [0, 1, 2, 3]

    def test_whole_bounds_give_every_cell(self) -> None:
        assert grid222().cells_overlapping(CUBE) == list(range(8))

    def test_box_partly_outside_is_clamped(self) -> None:
        box = BBox(1.5, -10, -10, 99, 0.5, 0.5)
        assert grid222().cells_overlapping(box) == [1]
        assert grid222().clamp(box) == BBox(1.5, 0, 0, 2, 0.5, 0.5)

    def test_box_around_the_bounds_gives_every_cell(self) -> None:
        assert grid222().cells_overlapping(BBox(-5, -5, -5, 5, 5, 5)) == list(range(8))

    def test_box_fully_outside_gives_nothing(self) -> None:
        assert grid222().cells_overlapping(BBox(3, 3, 3, 4, 4, 4)) == []
        assert grid222().cells_overlapping(BBox(0, 0, -9, 2, 2, -0.1)) == []
        assert grid222().clamp(BBox(3, 3, 3, 4, 4, 4)) is None

    def test_box_touching_the_upper_bound_from_outside_gets_the_last_cells(self) -> None:
        assert grid222().cells_overlapping(BBox(2, 2, 2, 3, 3, 3)) == [7]

    def test_face_on_an_inner_edge_touches_both_neighbours(self) -> None:
        assert grid222().cells_overlapping(BBox(0.2, 0.2, 0.2, 1, 0.8, 0.8)) == [0, 1]

    def test_point_box(self) -> None:
        assert grid222().cells_overlapping(BBox.around((1.5, 1.5, 0.5))) == [3]
        assert grid222().cells_overlapping(BBox.around((1, 1, 1))) == list(range(8))

    def test_default_grid(self) -> None:
        grid = SpatialGrid()
        home = BBox(-10, -10, 0, 10, 10, 2)  # straddles the four central columns
        assert len(grid.cells_overlapping(home)) == 4
        far = BBox(5000, 5000, 0, 6000, 6000, 1)
        assert grid.cells_overlapping(far) == []


class TestCellKey:
    def test_is_a_deterministic_160_bit_key(self) -> None:
        grid = grid222()
        key = grid.cell_key(3, "missions")
        assert key == grid222().cell_key(3, "missions")
        assert 0 <= key < 1 << 160
        assert key.bit_length() > 64  # a full hash, not the original's 16 bits

    def test_golden_value(self) -> None:
        # Changing the key derivation splits the swarm; bump _KEY_DOMAIN if you must.
        assert SpatialGrid().cell_key(0, "missions") == GOLDEN_KEY

    def test_every_cell_has_its_own_key(self) -> None:
        grid = SpatialGrid()
        keys = {grid.cell_key(i, "missions") for i in range(grid.cell_count)}
        assert len(keys) == grid.cell_count

    def test_depends_on_name_bounds_and_cells(self) -> None:
        key = grid222().cell_key(0, "missions")
        assert key != grid222().cell_key(0, "landmarks")
        assert key != SpatialGrid(CUBE, (2, 2, 1)).cell_key(0, "missions")
        assert key != SpatialGrid(BBox(0, 0, 0, 2, 2, 3), (2, 2, 2)).cell_key(0, "missions")

    def test_rejects_bad_arguments(self) -> None:
        with pytest.raises(ValueError, match="outside a grid"):
            grid222().cell_key(8, "missions")
        with pytest.raises(ValueError, match="non-empty name"):
            grid222().cell_key(0, "")
