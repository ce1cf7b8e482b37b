"""`mapctl bench mapping`: robots stream their missions through the chunks' Raft
groups; afterwards every holder holds exactly what was acknowledged (no speed
thresholds: the figures go to docs/benchmarks.md)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner

from mapbench.mapping import SEED_VERTICES, check_mapping
from mapbench.robot import Digest
from mapbench.workers import SwarmCheckFailed
from mapctl.cli import cli


@pytest.mark.slow
@pytest.mark.timeout(60)
@pytest.mark.parametrize("mode", [[], ["--cross-alone"]], ids=["with-the-batch", "alone"])
def test_every_acknowledged_item_is_on_every_holder(tmp_path: Path, mode: list[str]) -> None:
    robots, holders = 3, 2
    args = ["bench", "mapping", "-p", robots, "-k", holders, "-s", "1", "--batch", "10:20"]
    result = CliRunner().invoke(
        cli, [*map(str, args), *mode, "--cross", "0.2", "--dir", str(tmp_path), "--json"]
    )

    assert result.exit_code == 0, result.output
    figures = json.loads(result.stdout)
    chunks = figures["chunks"]
    assert len(chunks) == 2 * robots  # a vertex chunk and an edge chunk per robot
    for seen in chunks.values():
        assert len(seen["holders"]) == holders
        assert all(digest == seen["acked"] for digest in seen["holders"].values())
    acked = sum(seen["acked"][0] for seen in chunks.values())
    assert acked == figures["items"] + robots * SEED_VERTICES  # the seeds are not timed
    assert figures["multi_chunk_commits"] > 0  # inter-robot edges: two chunks each
    assert figures["commits"] >= figures["multi_chunk_commits"] + 2 * robots
    assert figures["bytes_per_item"] > 0
    assert figures["conflicts"] <= figures["retries"]
    assert list(tmp_path.iterdir()) == []  # the scratch repositories are gone


def _result(held: list[int]) -> dict[str, Any]:
    return {"chunks": {"c1": {"acked": [2, 7], "holders": {"peer0": [2, 7], "peer1": held}}}}


class TestCheckMapping:
    def test_equal_digests_pass(self) -> None:
        check_mapping(_result([2, 7]))

    def test_a_holder_missing_an_item_is_named(self) -> None:
        with pytest.raises(SwarmCheckFailed, match=r"peer1 holds \[1, 5\].*chunk c1"):
            check_mapping(_result([1, 5]))

    def test_a_holder_that_did_not_answer_for_a_chunk_fails(self) -> None:
        with pytest.raises(SwarmCheckFailed, match="peer1 holds None"):
            check_mapping({"chunks": {"c1": {"acked": [0, 0], "holders": {"peer1": None}}}})


def test_digests_do_not_depend_on_order_or_grouping() -> None:
    whole, parts = Digest(), Digest()
    whole.add(["a", "b", "c"])
    first, second = Digest(), Digest()
    first.add(["c"])
    second.add(["b", "a"])
    parts.merge(first.pair())
    parts.merge(second.pair())

    assert whole == parts
    assert whole != Digest(3, 0)
