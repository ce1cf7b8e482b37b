"""`mapctl bench scale` grows a repository mission by mission and times every read
command (no time thresholds: the figures go to docs/benchmarks.md)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from click.testing import CliRunner

from mapapi.core.errors import UsageError
from mapbench.carmen import main as carmen
from mapbench.scale import READS, copy_of, parse_counts
from mapctl.cli import cli


def _small_graph(path: Path, poses: int = 40) -> Path:
    """A small 2D g2o graph: a square spiral with odometry and one loop closure."""
    lines = [
        f"VERTEX_SE2 {i} {math.cos(i / 5) * i / 4:.3f} {math.sin(i / 5) * i / 4:.3f} {i / 5:.3f}"
        for i in range(poses)
    ]
    info = "100 0 0 100 0 1000"
    lines += [f"EDGE_SE2 {i} {i + 1} 0.5 0 0.2 {info}" for i in range(poses - 1)]
    lines.append(f"EDGE_SE2 0 {poses - 1} 1 1 0 {info}")
    path.write_text("\n".join(lines) + "\n")
    return path


def test_the_command_grows_the_repository_and_prints_one_json_object(tmp_path: Path) -> None:
    graph = _small_graph(tmp_path / "spiral.g2o")
    args = ["bench", "scale", "--missions", "2,1", "--graph", str(graph), "--runs", "1"]
    result = CliRunner().invoke(cli, [*args, "--label", "now", "--dir", str(tmp_path), "--json"])

    assert result.exit_code == 0, result.output
    figures = json.loads(result.stdout)
    assert (figures["graph"], figures["vertices"], figures["edges"]) == ("spiral.g2o", 40, 40)
    assert figures["label"] == "now"
    assert [p["missions"] for p in figures["points"]] == [1, 2]
    for point in figures["points"]:
        assert set(point["seconds"]) == set(READS)
        assert all(len(runs) == 1 for runs in point["runs_s"].values())
        assert point["store_bytes"] > 0
    assert [p.name for p in tmp_path.iterdir()] == ["spiral.g2o"]  # the scratch repository is gone


def test_copies_are_missions_of_their_own_apart_from_each_other(tmp_path: Path) -> None:
    from mapapi.maps.source import read_source

    (graph,) = read_source(_small_graph(tmp_path / "spiral.g2o"))
    first, second = copy_of(graph, 0), copy_of(graph, 1)  # type: ignore[arg-type]

    assert (first.name, second.name) == ("spiral-000", "spiral-001")
    assert {e.source[0] for e in second.edges} == {"spiral-001"}
    one, two = first.bbox(), second.bbox()
    assert one is not None
    assert two is not None
    assert not one.overlaps(two)


def test_mission_counts_are_parsed_and_checked() -> None:
    assert parse_counts("100,1, 10") == [1, 10, 100]
    for bad in ("", "0,1", "ten"):
        with pytest.raises(UsageError):
            parse_counts(bad)


def test_a_carmen_log_becomes_a_graph_of_its_scans(tmp_path: Path) -> None:
    ranges = " ".join(["1.0"] * 3)
    log = tmp_path / "tiny.clf"
    log.write_text(
        "PARAM robot_front_laser_max 50\n"
        f"FLASER 3 {ranges} 0 0 0 0 0 0 1.0 host 1.0\n"
        "ODOM 0 0 0 0 0 0 1.5 host 1.5\n"
        f"FLASER 3 {ranges} 1 0 0 1 0 1.5707963 2.0 host 2.0\n"
    )
    assert carmen([str(log), str(tmp_path / "tiny.g2o")]) == 0
    lines = (tmp_path / "tiny.g2o").read_text().splitlines()
    assert lines[:2] == [
        "VERTEX_SE2 0 0.000000 0.000000 0.000000",
        "VERTEX_SE2 1 1.000000 0.000000 1.570796",
    ]
    assert lines[2].startswith("EDGE_SE2 0 1 1.000000 0.000000 1.570796 ")
