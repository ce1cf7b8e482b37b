"""`mapctl bench triggers` on tiny swarms: the workload is what it promises,
every subscriber learns exactly the commits inside its region, and triggers
cost fewer bytes than polling (byte counts, never times, are compared)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner

from mapapi.core.errors import UsageError
from mapapi.lookup.spatial import BBox
from mapbench.trigger_workload import AREA, REGION, plan_workload
from mapbench.triggers import MODES, TriggersCheckFailed, check_triggers, measure_triggers
from mapctl.cli import cli

KEYS = {
    "mode",
    "inside_fraction",
    "writers",
    "subscribers",
    "peers",
    "items",
    "commits",
    "inside_commits",
    "bytes",
    "bytes_per_commit",
    "messages",
    "ring_bytes",
    "own_bytes",
    "ratio_to_polling",
    "setup_bytes",
    "query_bytes",
    "changes",
    "revisions",
    "network_bytes",
    "missed",
    "extra",
    "stale_rounds",
    "seconds",
    "bytes_by_round",
    "bytes_by_type",
}
TINY = {"writers": 1, "subscribers": 1, "peers": 3, "items": 10, "commits": 4}


def check_rows(rows: list[dict[str, Any]], fractions: list[float]) -> None:
    """One row per (fraction, mode) in order, the promised keys, every subscriber
    exact, and the bytes ordered as the modes promise."""
    assert [(r["inside_fraction"], r["mode"]) for r in rows] == [
        (f, m) for f in fractions for m in MODES
    ]
    for fraction in fractions:
        by_mode = {r["mode"]: r for r in rows if r["inside_fraction"] == fraction}
        for mode, row in by_mode.items():
            assert set(row) == KEYS
            assert (row["missed"], row["extra"], row["stale_rounds"]) == (0, 0, 0), mode
            assert len(row["bytes_by_round"]) == TINY["commits"]
            assert row["ring_bytes"] == by_mode["idle"]["bytes"]
        inside = by_mode["triggers"]["inside_commits"]
        # one item per commit: a change is a commit; idle follows nothing
        assert by_mode["triggers"]["changes"] == by_mode["triggers"]["revisions"] == inside
        assert by_mode["polling"]["changes"] == by_mode["replication"]["changes"] == inside
        assert by_mode["idle"]["changes"] == 0
        # every poll fetches the whole history: the items, then one more revision a round
        commits, items = TINY["commits"], TINY["items"]
        assert by_mode["polling"]["revisions"] == commits * items + commits * (commits + 1) / 2
        assert by_mode["replication"]["revisions"] == commits
        assert by_mode["triggers"]["bytes"] < by_mode["polling"]["bytes"]
        assert by_mode["triggers"]["ratio_to_polling"] < 1
        assert by_mode["polling"]["ratio_to_polling"] == 1
        assert by_mode["polling"]["query_bytes"] > 0
        assert by_mode["triggers"]["query_bytes"] == 0
        assert "trigger_push" in by_mode["triggers"]["bytes_by_type"]
        assert "raft_batch" in by_mode["polling"]["bytes_by_type"]  # each poll's snapshot


class TestWorkload:
    def test_exactly_the_share_asked_is_inside(self) -> None:
        workload = plan_workload(3, 20, 10, 0.3, seed=1)
        assert workload.inside_commits() == 3 * 3
        for updates in workload.rounds:
            assert len(updates) == 3
        assert plan_workload(3, 20, 10, 0.3, seed=1) == workload

    def test_items_stay_on_their_side_and_no_chunk_box_grows(self) -> None:
        workload = plan_workload(2, 12, 30, 0.5, seed=2)
        for w, start in enumerate(workload.items):
            extent = BBox.enclosing(start)
            assert (extent.mins[:2], extent.maxs[:2]) == (AREA.mins[:2], AREA.maxs[:2])
            inside = {k for k, box in enumerate(start) if box.overlaps(REGION)}
            assert 1 <= len(inside) < len(start)
            for updates in workload.rounds:
                update = updates[w]
                assert update.before.overlaps(REGION) == update.after.overlaps(REGION)
                assert (update.item in inside) == update.inside(REGION)
                assert AREA.intersection(update.after) == update.after

    def test_bad_sizes_are_refused(self) -> None:
        with pytest.raises(ValueError, match="3 items"):
            plan_workload(1, 2, 5, 0.1)
        with pytest.raises(ValueError, match="fraction"):
            plan_workload(1, 10, 5, 1.5)


class TestMeasureTriggers:
    def test_every_mode_learns_exactly_the_inside_commits(self) -> None:
        rows = measure_triggers(fractions=(0.5,), seed=3, **TINY)
        check_rows(rows, [0.5])
        check_triggers(rows)

    def test_too_few_peers_are_refused(self) -> None:
        with pytest.raises(UsageError, match="give more --peers"):
            measure_triggers(writers=2, subscribers=2, peers=3)

    def test_a_missed_commit_fails_the_check(self) -> None:
        row = {"mode": "triggers", "inside_fraction": 0.1, "missed": 1, "extra": 0}
        check_triggers([{**row, "missed": 0, "stale_rounds": 0}])
        with pytest.raises(TriggersCheckFailed, match=r"triggers at 0\.1 \(1 missed"):
            check_triggers([{**row, "stale_rounds": 1}])


class TestCommand:
    def test_json_prints_one_object_per_row_and_the_plot(self, tmp_path: Path) -> None:
        pytest.importorskip("matplotlib")
        png = tmp_path / "triggers.png"
        args = ["bench", "triggers", "-f", "0.25", "-f", "0.5", "-w", "1", "-s", "1", "-p", "3"]
        args += ["--items", "10", "-n", "4", "--json", "--plot", str(png)]
        result = CliRunner().invoke(cli, args)
        assert result.exit_code == 0, result.output
        check_rows([json.loads(line) for line in result.output.splitlines()], [0.25, 0.5])
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    def test_without_json_a_table_names_the_figures(self) -> None:
        args = ["bench", "triggers", "-f", "0.5", "-m", "triggers", "-m", "polling"]
        args += ["-w", "1", "-s", "1", "-p", "2", "--items", "5", "-n", "2"]
        result = CliRunner().invoke(cli, args)
        assert result.exit_code == 0, result.output
        assert "bench triggers: polling, 0.5 inside the region" in result.output
        for key in ("bytes", "ratio_to_polling", "missed", "stale_rounds"):
            assert key in result.output, key
