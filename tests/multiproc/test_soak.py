"""`mapctl bench soak`, sized for the test suite (issue 7 §7, issue 13 §4): peer
daemons commit while others are killed with SIGKILL, stopped, paused with
SIGSTOP and started again (half of the restarts on a new port); the checker must
find every acknowledged commit, the bank total intact and one history."""

from __future__ import annotations

import json
import subprocess

import pytest

from .conftest import MAPCTL

pytestmark = pytest.mark.slow

SECONDS = 25


def test_a_short_soak_keeps_every_invariant() -> None:
    done = subprocess.run(
        [MAPCTL, "bench", "soak", "--minutes", str(SECONDS / 60), "--seed", "3", "--json"],
        capture_output=True,
        text=True,
        timeout=SECONDS + 180,
        check=False,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    result = json.loads(done.stdout)
    assert set(result) >= {"commits", "crashes", "restarts", "invariants_ok", "lost_commits"}
    assert result["invariants_ok"] is True, result["problems"]
    assert result["lost_commits"] == 0
    assert result["errors"] == []
    assert result["crashes"] + result["stops"] + result["pauses"] >= 2  # the chaos really ran
    assert result["restarts"] >= result["crashes"] + result["stops"]
    assert result["increments"] > 0
    assert result["transfers"] > 0
    assert result["counter"] >= result["increments"]
    assert result["bank_total"] == [800]
