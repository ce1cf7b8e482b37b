"""The swarm benchmarks' checks, figures and plots (no speed thresholds)."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner

from mapbench.swarm import SwarmCheckFailed, check_viewtest, commit_latency, percentile
from mapctl.cli import cli

VIEWTEST_KEYS = (
    "peers",
    "n",
    "expected",
    "final",
    "commits_per_s",
    "aborts_per_commit",
    "p50_ms",
    "p99_ms",
)


def _result(**changes: Any) -> dict[str, Any]:
    base = {
        "peers": 2,
        "n": 3,
        "expected": 6,
        "final": 6,
        "values": [6, 6],
        "log_lengths": [7, 7],
        "logs_identical": True,
    }
    return {**base, **changes}


class TestCheckViewtest:
    def test_agreeing_peers_pass(self) -> None:
        check_viewtest(_result())

    def test_disagreeing_peers_name_every_value(self) -> None:
        with pytest.raises(SwarmCheckFailed, match=r"disagree.*\[6, 5\]"):
            check_viewtest(_result(final=None, values=[6, 5]))

    def test_a_lost_increment_is_counted(self) -> None:
        with pytest.raises(SwarmCheckFailed, match="1 increment"):
            check_viewtest(_result(final=5, values=[5, 5]))

    def test_diverging_logs_fail(self) -> None:
        with pytest.raises(SwarmCheckFailed, match="logs differ"):
            check_viewtest(_result(logs_identical=False, log_lengths=[7, 6]))


def test_percentile_is_nearest_rank() -> None:
    values = [float(v) for v in range(1, 101)]
    assert percentile(values, 0.5) == 51.0
    assert percentile(values, 0.99) == 100.0
    with pytest.raises(ValueError, match="no samples"):
        percentile([], 0.5)


def test_plots_are_written(tmp_path: Path) -> None:
    pytest.importorskip("matplotlib")
    from mapbench.plot import load_results, plot_commit, plot_viewtest

    views = tmp_path / "viewtest.jsonl"
    views.write_text(
        "\n".join(
            json.dumps({"peers": p, "commits_per_s": 100.0 * p, "aborts_per_commit": 0.5})
            for p in (1, 2, 2, 4)
        )
    )
    commits = tmp_path / "commit.jsonl"
    commits.write_text(
        "\n".join(
            json.dumps(
                {"holders": k, "writer": w, "p50_ms": k, "p99_ms": 2 * k, "messages_per_commit": k}
            )
            for k in (1, 2, 3)
            for w in ("follower", "leader")
        )
        + "\n\n"
    )
    plot_viewtest(load_results([views]), tmp_path / "v.png")
    plot_commit(load_results([commits]), tmp_path / "c.png")
    for png in ("v.png", "c.png"):
        assert (tmp_path / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.slow
def test_viewtest_command_prints_the_promised_json(tmp_path: Path) -> None:
    result = CliRunner().invoke(
        cli, ["bench", "viewtest", "--peers", "2", "-n", "5", "--dir", str(tmp_path), "--json"]
    )
    assert result.exit_code == 0, result.output
    figures = json.loads(result.output)
    for key in VIEWTEST_KEYS:
        assert key in figures, key
    assert figures["final"] == figures["expected"] == 10
    assert figures["logs_identical"]
    assert list(tmp_path.iterdir()) == []  # the scratch repositories are gone


@pytest.mark.slow
def test_commit_latency_counts_messages_of_every_holder(tmp_path: Path) -> None:
    figures = commit_latency(2, 5, writer="leader", directory=tmp_path, warmup=1)
    assert figures["writer"] == "leader"
    # at least the entry's append to the other holder and its answer (heartbeats add more)
    assert figures["messages_per_commit"] >= 2.0
    assert figures["p50_ms"] > 0


@pytest.mark.slow
def test_a_secure_swarm_commits_with_the_same_messages(tmp_path: Path) -> None:
    figures = commit_latency(2, 5, writer="leader", directory=tmp_path, warmup=1, secure=True)
    assert figures["secure"] is True
    assert figures["messages_per_commit"] >= 2.0  # the same protocol over CurveZMQ


def test_the_swarm_script_asks_only_for_writers_bench_commit_knows() -> None:
    """`scripts/bench-swarm.sh` (make bench-swarm) outlived a rename once: its
    `--writer` values must be the command's choices."""
    script = (Path(__file__).resolve().parents[2] / "scripts" / "bench-swarm.sh").read_text()
    (loop,) = re.findall(r"for writer in ([\w ]+); do", script)
    command = cli.commands["bench"].commands["commit"]  # type: ignore[attr-defined]
    (writer,) = [p for p in command.params if p.name == "writer"]
    assert set(loop.split()) == set(writer.type.choices)
