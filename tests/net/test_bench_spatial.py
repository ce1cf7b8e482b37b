"""`mapctl bench spatial` on tiny grids: the promised figures, and the missions
found equal a brute-force overlap count over the same missions and boxes
(times are reported, never asserted)."""

from __future__ import annotations

import json
import statistics
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner

from mapapi.core.errors import UsageError
from mapapi.lookup.spatial import BBox
from mapbench.spatial import (
    SpatialCheckFailed,
    check_spatial,
    grid_for,
    load_dataset,
    measure_spatial,
    query_boxes,
)
from mapbench.spatial_tiles import pose_boxes
from mapctl.cli import cli

SAMPLES = Path(__file__).resolve().parents[2] / "sample_maps"
GARAGE = SAMPLES / "pose_graphs" / "parking-garage.g2o"
KEYS = {
    "dataset",
    "cells",
    "latency_ms",
    "peers",
    "missions",
    "queries",
    "cells_asked",
    "query_ms",
    "query_ms_all",
    "requests",
    "returned_exact",
    "returned_all",
    "matches",
    "tiles",
    "tiles_found",
    "rows_moved",
    "bytes_moved",
    "rows_whole",
    "bytes_whole",
    "share_moved",
    "share_moved_max",
    "mismatches",
}


def brute_force(dataset: str, boxes: list[BBox]) -> dict[str, float]:
    """Per query box on average, the oracle: the missions and tiles whose box
    overlaps it, and the rows of those tiles plus one per mission's row."""
    data = load_dataset(dataset, SAMPLES)
    missions = [sum(m.overlaps(box) for m in data.missions.values()) for box in boxes]
    tiles = [[t for t in data.tiles if t.bbox.overlaps(box)] for box in boxes]
    return {
        "matches": statistics.fmean(missions),
        "tiles_found": statistics.fmean(len(hit) for hit in tiles),
        "rows_moved": statistics.fmean(
            found + sum(t.rows for t in hit) for found, hit in zip(missions, tiles, strict=True)
        ),
    }


def check_rows(rows: list[dict[str, Any]], dataset: str, cells: list[int], queries: int) -> None:
    """One row per cell count in order, the promised keys, and what was found as
    brute force finds it."""
    boxes = query_boxes(load_dataset(dataset, SAMPLES), queries, seed=3)
    expected = brute_force(dataset, boxes)
    assert [row["cells"] for row in rows] == cells
    for row in rows:
        assert set(row) == KEYS
        assert (row["dataset"], row["latency_ms"], row["queries"]) == (dataset, 0, queries)
        assert {k: row[k] for k in expected} == pytest.approx(expected, abs=1e-3)
        assert row["matches"] + row["tiles_found"] <= row["returned_exact"] <= row["returned_all"]
        assert 1 <= row["cells_asked"] <= row["cells"]
        assert row["rows_moved"] <= row["rows_whole"]
        assert row["bytes_moved"] <= row["bytes_whole"]
        assert 0 <= row["share_moved"] <= row["share_moved_max"] <= 1
    first = rows[0]  # one cell holds every chunk: all of them travel without filtering
    assert first["returned_all"] == first["missions"] + first["tiles"]
    assert first["returned_exact"] == first["matches"] + first["tiles_found"]


class TestGeometry:
    def test_the_vertical_axis_of_each_data_set_stays_undivided(self) -> None:
        assert grid_for(load_dataset("parking-garage", SAMPLES), 16).cells == (4, 4, 1)
        assert grid_for(load_dataset("tunnels", SAMPLES), 16).cells == (4, 1, 4)  # y down

    def test_missions_are_robots_or_garage_segments(self) -> None:
        assert len(load_dataset("tunnels", SAMPLES).missions) == 8
        assert len(load_dataset("parking-garage", SAMPLES).missions) == 17  # 1,661 / 100

    def test_a_g2o_file_is_a_data_set_of_its_tiled_missions(self) -> None:
        garage = load_dataset(str(SAMPLES / "pose_graphs" / "parking-garage.g2o"))
        assert (garage.name, list(garage.missions)) == ("parking-garage", ["parking-garage"])
        (part,) = garage.parts.values()
        assert len(part.tiles) == 12  # 1,661 poses over 270 m
        assert part.rows == 1 + 1_661 + 6_275
        assert part.bytes == part.row_bytes + sum(t.bytes for t in part.tiles)
        with pytest.raises(UsageError, match=r"or a \.g2o file"):
            load_dataset("nowhere")

    def test_a_grid_that_is_not_square_is_refused(self) -> None:
        with pytest.raises(UsageError, match="not n x n"):
            grid_for(load_dataset("tunnels", SAMPLES), 8)

    def test_query_boxes_are_seeded_and_inside_the_extent(self) -> None:
        dataset = load_dataset("tunnels", SAMPLES)
        boxes = query_boxes(dataset, 5, seed=1)
        assert boxes == query_boxes(dataset, 5, seed=1)
        assert all(dataset.extent.intersection(box) == box for box in boxes)


class TestMeasureSpatial:
    def test_matches_equal_a_brute_force_count(self) -> None:
        rows = measure_spatial(
            "tunnels", cells=(1, 4, 16), latencies_ms=(0,), peers=4, queries=2, seed=3
        )
        check_rows(rows, "tunnels", [1, 4, 16], 2)

    def test_a_mismatch_between_the_modes_fails_the_check(self) -> None:
        row = {"dataset": "tunnels", "cells": 4, "latency_ms": 0.0, "mismatches": 1}
        check_spatial([{**row, "mismatches": 0}])
        with pytest.raises(SpatialCheckFailed, match="tunnels 4 cells"):
            check_spatial([row])


class TestCommand:
    def test_json_prints_one_object_per_row_and_the_plot(self, tmp_path: Path) -> None:
        pytest.importorskip("matplotlib")
        png = tmp_path / "spatial.png"
        args = ["bench", "spatial", "-d", "parking-garage", "-c", "1", "-c", "16", "-l", "0"]
        args += ["-n", "2", "-p", "4", "--seed", "3", "--json", "--plot", str(png)]
        result = CliRunner().invoke(cli, args)
        assert result.exit_code == 0, result.output
        rows = [json.loads(line) for line in result.output.splitlines()]
        check_rows(rows, "parking-garage", [1, 16], 2)
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    def test_without_json_a_table_names_the_figures(self) -> None:
        args = ["bench", "spatial", "-d", "tunnels", "-c", "4", "-l", "0", "-n", "2", "-p", "4"]
        result = CliRunner().invoke(cli, args)
        assert result.exit_code == 0, result.output
        assert "bench spatial: tunnels, 4 cells, 0 ms" in result.output
        for key in KEYS - {"dataset", "cells", "latency_ms"}:
            assert key in result.output, key


def test_boxes_around_poses_each_hold_their_share_of_the_poses() -> None:
    garage = load_dataset(str(GARAGE))
    (part,) = garage.parts.values()
    boxes = pose_boxes(garage.parts, garage.extent, garage.vertical, 20, 0.05, seed=1)
    assert boxes == pose_boxes(garage.parts, garage.extent, garage.vertical, 20, 0.05, seed=1)
    for box in boxes:
        inside = sum(box.overlaps(BBox(*p, *p)) for p in part.points)
        assert inside >= 0.05 * len(part.points)  # the smallest square that holds 5 %
        assert (box.zmin, box.zmax) == (garage.extent.zmin, garage.extent.zmax)
    rows = measure_spatial(
        str(GARAGE),
        cells=(4,),
        latencies_ms=(0,),
        peers=3,
        queries=5,
        fraction=0.05,
        around_poses=True,
    )
    assert rows[0]["tiles_found"] >= 1
    assert rows[0]["share_moved"] < 1
