"""Helpers for tests that drive real `mapctl` processes."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

COMMAND_TIMEOUT = 30.0


def _mapctl_path() -> str:
    found = shutil.which("mapctl", path=str(Path(sys.executable).parent)) or shutil.which("mapctl")
    assert found, "mapctl is not installed next to the test interpreter"
    return found


MAPCTL = _mapctl_path()


def run_mapctl(
    repo: Path, *args: str, view: str = "main", ok: tuple[int, ...] = (0,)
) -> subprocess.CompletedProcess[str]:
    """Run one `mapctl -C repo --view VIEW ARGS` process; check its exit code against `ok`."""
    done = subprocess.run(
        [MAPCTL, "-C", str(repo), "--view", view, *args],
        capture_output=True,
        text=True,
        timeout=COMMAND_TIMEOUT,
        check=False,
    )
    assert done.returncode in ok, (
        f"mapctl -C {repo.name} {' '.join(args)} exited {done.returncode}: {done.stderr}"
    )
    return done
