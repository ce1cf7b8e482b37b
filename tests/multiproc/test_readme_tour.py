"""The README's 5-minute tour runs as printed (`make tour`, scripts/tour.sh)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[2]


def test_the_readme_tour_runs_as_printed() -> None:
    here = str(Path(sys.executable).parent)  # this interpreter's mapctl
    done = subprocess.run(
        ["bash", str(ROOT / "scripts" / "tour.sh")],
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "PATH": f"{here}{os.pathsep}{os.environ.get('PATH', '')}"},
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert "bob's commit conflicts (exit 3)" in done.stdout
    assert done.stdout.rstrip().endswith("== tour finished")
