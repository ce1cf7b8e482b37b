"""Three `mapctl` processes increment one counter through the CLI's view loop.

Each worker owns a named view and loops `view open` -> `get --json` -> `set` ->
`commit`; a commit that exits 3 (conflict) is followed by `view abort` and a
retry. No increment may be lost: the final value is a0 + 3*K and the log has
exactly 1 + 3*K commits (paper Algorithm 1 over the CLI, DESIGN §9).
"""

from __future__ import annotations

import json
import subprocess
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import pytest

from .conftest import COMMAND_TIMEOUT, MAPCTL, run_mapctl

WORKERS, K, A0 = 3, 6, 5
EXIT_CONFLICT = 3

# Each increment is four `mapctl` processes or more (a conflict retries them all): at K = 10,
# 150 and more processes took 85 s alone and 128 s beside another test on 2 cores, past the
# default 120 s cap. The cap guards against a hang; this test's own wait is the futures'.
pytestmark = [pytest.mark.slow, pytest.mark.timeout(300)]


def mapctl(repo: Path, *args: str, view: str = "main", ok: tuple[int, ...] = (0,)) -> Any:
    """Run one `mapctl -C repo --view VIEW ...`; the completed process (checked against `ok`)."""
    return run_mapctl(repo, *args, view=view, ok=ok)


def increment(repo: Path, view: str, item_id: str) -> int:
    """One increment through the CLI, retried on conflict; returns the conflicts seen."""
    conflicts = 0
    while True:
        mapctl(repo, "view", "open", view=view)
        fields = json.loads(mapctl(repo, "get", "counters", item_id, "--json", view=view).stdout)
        value = int(fields.get("value", 0)) + 1  # int64 is a JSON string; 0 is omitted
        data = json.dumps({"name": fields["name"], "value": value})
        mapctl(repo, "set", "counters", item_id, data, view=view)
        done = mapctl(repo, "commit", "-m", f"{view} -> {value}", view=view, ok=(0, EXIT_CONFLICT))
        if done.returncode == 0:
            return conflicts
        conflicts += 1
        mapctl(repo, "view", "abort", view=view)


def test_three_cli_processes_lose_no_increment(tmp_path: Path) -> None:
    repo = tmp_path / "repo"
    subprocess.run([MAPCTL, "init", str(repo)], check=True, timeout=COMMAND_TIMEOUT)
    mapctl(repo, "table", "create", "counters", "--type", "mapapi.v1.Counter")
    mapctl(repo, "chunk", "create", "counters")
    created = mapctl(repo, "set", "counters", json.dumps({"name": "c", "value": A0}), "--json")
    item_id = json.loads(created.stdout)["id"]
    mapctl(repo, "commit", "-m", "insert c")

    def worker(index: int) -> int:
        return sum(increment(repo, f"p{index}", item_id) for _ in range(K))

    with ThreadPoolExecutor(max_workers=WORKERS) as pool:
        futures = [pool.submit(worker, i) for i in range(WORKERS)]
        for future in futures:
            future.result(timeout=WORKERS * K * 4 * COMMAND_TIMEOUT)

    final = json.loads(mapctl(repo, "get", "counters", item_id, "--json").stdout)
    assert final["value"] == A0 + WORKERS * K
    log = json.loads(mapctl(repo, "log", "--json").stdout)
    assert len(log) == 1 + WORKERS * K
    assert json.loads(mapctl(repo, "view", "list", "--json").stdout) == {"views": []}
