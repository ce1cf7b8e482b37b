"""`mapctl bench lookup` on small rings: the promised figures, exact answers and
plausible hop counts (latencies are reported, never asserted)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner

from mapbench.lookup import measure_lookups, target_mean_hops
from mapctl.cli import cli

PROMISED = {"peers", "mean_hops", "p99_hops", "p50_ms", "p99_ms", "errors"}
EXTRA = {"lookups", "target_mean_hops", "setup_s"}


def check_figures(figures: dict[str, Any], peers: int, lookups: int) -> None:
    """The promised keys (and only the allowed extras), no error, plausible hops."""
    assert PROMISED <= set(figures) <= PROMISED | EXTRA
    assert (figures["peers"], figures["lookups"], figures["errors"]) == (peers, lookups, 0)
    assert figures["target_mean_hops"] == pytest.approx(target_mean_hops(peers), abs=1e-3)
    # the bounds of tests/swarm/test_chord.py: O(log N) hops once fingers are fixed
    assert 0 <= figures["mean_hops"] <= figures["p99_hops"] <= 2 * math.log2(peers) + 2
    assert figures["mean_hops"] <= math.log2(peers) + 1
    assert 0 < figures["p50_ms"] <= figures["p99_ms"]


class TestMeasureLookups:
    def test_every_answer_on_eight_nodes_matches_the_oracle(self) -> None:
        check_figures(measure_lookups(8, 100, seed=1), 8, 100)

    def test_a_seed_repeats_the_hop_counts(self) -> None:
        first, second = (measure_lookups(8, 30, seed=2) for _ in range(2))
        assert (first["mean_hops"], first["p99_hops"]) == (second["mean_hops"], second["p99_hops"])

    def test_a_lone_node_answers_every_lookup_itself(self) -> None:
        figures = measure_lookups(1, 10)
        assert (figures["mean_hops"], figures["p99_hops"], figures["errors"]) == (0, 0, 0)

    def test_an_empty_ring_is_refused(self) -> None:
        with pytest.raises(ValueError, match="at least 1 peer"):
            measure_lookups(0, 10)


class TestCommand:
    def test_json_prints_one_object_per_ring_in_the_order_given(self, tmp_path: Path) -> None:
        pytest.importorskip("matplotlib")
        png = tmp_path / "lookup.png"
        args = ["bench", "lookup", "-p", "8", "-p", "4", "-n", "40", "--json", "--plot", str(png)]
        result = CliRunner().invoke(cli, args)
        assert result.exit_code == 0, result.output
        rows = [json.loads(line) for line in result.output.splitlines()]
        assert [row["peers"] for row in rows] == [8, 4]
        for row in rows:
            check_figures(row, row["peers"], 40)
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    def test_without_json_a_table_names_the_figures(self) -> None:
        result = CliRunner().invoke(cli, ["bench", "lookup", "--peers", "8", "--lookups", "20"])
        assert result.exit_code == 0, result.output
        assert "bench lookup: 8 peers" in result.output
        for key in PROMISED:
            assert key in result.output, key
