"""`mapctl bench import` reports every phase of a real import (no speed thresholds:
the figures go to docs/benchmarks.md)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from click.testing import CliRunner

from mapapi.core.errors import UsageError
from mapbench.maps import measure_import
from mapctl.cli import cli

RATES = ("parse_per_s", "parse_stage_per_s", "end_to_end_per_s")


@pytest.mark.parametrize("store", ["sqlite", "memory"])
def test_intel_figures_on_each_store(store: str, tmp_path: Path) -> None:
    result = measure_import("intel", runs=1, store=store, directory=tmp_path)

    assert (result["dataset"], result["store"], result["missions"]) == ("intel", store, 1)
    assert result["elements"] == 4_240
    for key in ("parse_s", "stage_s", "commit_s", *RATES):
        assert result[key] > 0, key
    assert result["parse_per_s"] > result["parse_stage_per_s"] > result["end_to_end_per_s"]
    assert list(tmp_path.iterdir()) == []  # the scratch repository is gone


def test_unknown_data_sets_and_stores_are_refused() -> None:
    with pytest.raises(UsageError, match="unknown data set"):
        measure_import("new-college")
    with pytest.raises(UsageError, match="unknown store"):
        measure_import("intel", store="redis")


def test_the_command_prints_one_json_object_per_data_set() -> None:
    args = ["bench", "import", "--dataset", "tunnels", "--store", "memory", "--runs", "1"]
    result = CliRunner().invoke(cli, [*args, "--json"])
    assert result.exit_code == 0, result.output
    (row,) = [json.loads(line) for line in result.stdout.splitlines()]
    assert (row["dataset"], row["missions"], row["elements"]) == ("tunnels", 8, 6_146)


def test_any_map_file_is_measured_with_its_points(tmp_path: Path) -> None:
    log = Path(__file__).resolve().parents[2] / "sample_maps" / "laser_logs" / "intel-head.clf.bz2"
    args = ["bench", "import", "--file", str(log), "--store", "memory", "--runs", "1", "--json"]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output
    row = json.loads(result.stdout)
    assert (row["dataset"], row["elements"]) == ("intel-head.clf.bz2", 671 + 670)
    assert row["points"] > 100_000
    refused = CliRunner().invoke(cli, [*args, "--dataset", "intel"])
    assert refused.exit_code == 2


def test_the_landmark_and_per_robot_sets_are_measured() -> None:
    """Landmarks count as elements, like vertices (issue 17's import rates)."""
    victoria = measure_import("victoria-park", runs=1, store="memory")
    dgs = measure_import("dgs-blocks", runs=1, store="memory")
    assert (victoria["missions"], victoria["elements"]) == (1, 6_969 + 151 + 10_608)
    assert (dgs["missions"], dgs["elements"]) == (4, 64 + 144)
