"""`mapctl bench registration` at a tiny size: real peers on loopback fetch the
missions their jobs need through the swarm, both modes register them to the
same frames, and the figures are what they claim (bytes and counts are
compared, never times)."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import pytest
from click.testing import CliRunner

from mapapi.core.errors import UsageError
from mapapi.maps.graph import EdgeKind
from mapbench.registration import (
    RegistrationCheckFailed,
    check_registration,
    cut,
    measure_registration,
    plan,
)
from mapctl.cli import cli
from tests.cli.conftest import run_main

FAST = {"decentralized": 20e6, "centralized": 10e6}  # bytes/s: shaped, but quick
PEER_KEYS = {
    "peer",
    "role",
    "missions",
    "chunks",
    "bytes",
    "transfer_s",
    "load_s",
    "register_s",
    "compute_s",
    "total_s",
}


class TestPlan:
    def test_roles_jobs_and_cut(self) -> None:
        layout = plan(ground=2, aerial=1, vertices=20)
        assert [g.name for g in layout.ground] == ["robot0", "robot1"]
        assert [g.name for g in layout.aerial] == ["robot7"]
        # robot1's first 20 poses share fewer than 3 edges with robot7's
        assert layout.jobs == {"robot0": ["robot7"], "robot1": []}
        for graph in layout.missions:
            assert sorted(graph.vertices) == list(range(20))
            assert all(max(e.source[1], e.target[1]) < 20 for e in graph.edges)

    def test_cut_keeps_the_edges_among_kept_vertices_of_the_missions_given(self) -> None:
        whole = plan(ground=1, aerial=1)
        robot0, robot7 = cut(whole.missions, 10)
        assert (sorted(robot0.vertices), sorted(robot7.vertices)) == (list(range(10)),) * 2
        assert robot0.count(EdgeKind.ODOMETRY) == 9
        assert robot0.edges == [
            e
            for e in whole.ground[0].edges
            if {e.source[0], e.target[0]} <= {"robot0", "robot7"}
            and max(e.source[1], e.target[1]) < 10
        ]
        assert robot0.count(EdgeKind.INTER_ROBOT) > 0

    @pytest.mark.parametrize(
        ("sizes", "message"),
        [
            ({"ground": 0, "aerial": 1}, "at least 1 of each"),
            ({"ground": 5, "aerial": 4}, "do not fit the 8 robots"),
            ({"ground": 1, "aerial": 1, "vertices": 1}, "at least 2 vertices"),
        ],
    )
    def test_bad_sizes_are_refused(self, sizes: dict[str, int], message: str) -> None:
        with pytest.raises(UsageError, match=message):
            plan(**sizes)


def check_result(result: dict[str, Any]) -> None:
    """Both modes ran the plan of `plan(2, 1, 20)` and agree."""
    decentralized, centralized = result["runs"]
    assert (decentralized["mode"], centralized["mode"]) == ("decentralized", "centralized")
    robot0, robot1 = decentralized["peers"]
    (server,) = centralized["peers"]
    for row in (robot0, robot1, server):
        assert set(row) == PEER_KEYS
        assert row["compute_s"] == pytest.approx(row["load_s"] + row["register_s"], abs=2e-3)
    assert (robot0["peer"], robot0["missions"], robot0["chunks"]) == ("robot0", ["robot7"], 3)
    assert robot0["bytes"] > 0
    assert (robot1["missions"], robot1["bytes"], robot1["transfer_s"]) == ([], 0, 0.0)
    assert server["missions"] == ["robot0", "robot1", "robot7"]
    assert server["chunks"] == 9
    assert server["bytes"] > robot0["bytes"]  # everything robot0 fetched, and more
    assert decentralized["bytes"] == robot0["bytes"]
    assert decentralized["wall_s"] == max(robot0["total_s"], robot1["total_s"])
    (mine,) = decentralized["registrations"]
    (theirs,) = centralized["registrations"]
    assert (mine["reference"], mine["missions"]) == ("robot0", ["robot7"])
    assert {k: v for k, v in mine.items() if k != "frames"} == {
        k: v for k, v in theirs.items() if k != "frames"
    }
    assert mine["frames"]["robot7"] == pytest.approx(theirs["frames"]["robot7"], abs=1e-9)
    assert 0 < mine["inliers"] <= mine["edges"]
    assert mine["rms_m_after"] < mine["rms_m_before"]
    assert result["frame_difference_m"] < 1e-9


class TestMeasure:
    def test_both_modes_fetch_what_they_need_and_agree(self) -> None:
        result = measure_registration(plan(ground=2, aerial=1, vertices=20), bandwidths=FAST)
        check_result(result)
        check_registration(result)

    def test_frames_apart_fail_the_check(self) -> None:
        result = {"frame_difference_m": 0.5, "frame_difference_deg": 0.0, "runs": []}
        with pytest.raises(RegistrationCheckFailed, match=r"0\.5 m"):
            check_registration(result)
        check_registration({**result, "frame_difference_m": None, "frame_difference_deg": None})

    def test_an_unknown_mode_is_refused(self) -> None:
        with pytest.raises(UsageError, match="unknown modes"):
            measure_registration(plan(ground=1, aerial=1, vertices=5), modes=("anarchy",))


def speeds(fast: float, slow: float) -> list[str]:
    return ["--decentralized-bandwidth", str(fast), "--centralized-bandwidth", str(slow)]


class TestCommand:
    def test_json_and_the_plot(self, tmp_path: Path) -> None:
        pytest.importorskip("matplotlib")
        png = tmp_path / "registration.png"
        args = ["bench", "registration", "--quick", "--ground", "2", "--aerial", "1"]
        args += ["--vertices", "20", *speeds(20_000, 10_000), "--json", "--plot", str(png)]
        result = CliRunner().invoke(cli, args)
        assert result.exit_code == 0, result.output
        check_result(json.loads(result.output))
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    def test_quick_without_json_prints_the_tables(self) -> None:
        args = ["bench", "registration", "--quick", *speeds(20_000, 10_000)]
        result = CliRunner().invoke(cli, args)
        assert result.exit_code == 0, result.output
        for text in (
            "bench registration: decentralized, 20000 kB/s links",
            "bench registration: centralized, 10000 kB/s links",
            "robot6, robot7",  # each ground robot's neighbours at 50 vertices
            "frames differ between the modes by at most",
        ):
            assert text in result.output, text

    def test_without_gtsam_it_exits_2_saying_what_to_install(
        self, monkeypatch: pytest.MonkeyPatch
    ) -> None:
        monkeypatch.setitem(sys.modules, "gtsam", None)  # import gtsam raises ImportError
        outcome = run_main(["bench", "registration", "--quick"])
        assert outcome.code == 2
        assert outcome.err_lines == [
            "error: registration needs gtsam; install it with `pip install 'mapapi[registration]'`"
        ]
        assert outcome.out == ""
