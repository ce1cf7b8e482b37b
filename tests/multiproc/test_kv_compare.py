"""`scripts/kv-compare.sh` (`mapbench.kv_compare`): paper Algorithm 1 against Redis and a
3-member etcd cluster it starts itself; every counter reads P*N, and no server is left
running (skipped where the Debian packages are not installed). No speed thresholds."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

from mapbench.kv_compare import rows, table

pytestmark = [pytest.mark.slow, pytest.mark.timeout(120)]


def _children() -> list[str]:
    """Command lines of this process's live child processes."""
    found = []
    for status in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = status.read_text().rsplit(")", 1)[1].split()
            if int(fields[1]) == os.getpid() and fields[0] != "Z":
                found.append((status.parent / "cmdline").read_text().replace("\0", " "))
        except (OSError, IndexError, ValueError):
            continue  # a process that exited meanwhile
    return found


@pytest.mark.parametrize("system", ["redis", "etcd"])
def test_every_increment_counts_and_the_servers_stop(system: str) -> None:
    program = {"redis": "redis-server", "etcd": "etcd"}[system]
    if shutil.which(program) is None:
        pytest.skip(f"{program} is not installed (apt-get install -y redis-server etcd-server)")

    found = list(rows([system], [1, 2], 20))  # raises unless the counter reads P*N

    assert [(r["system"], r["procs"]) for r in found] == [(system, 1), (system, 2)]
    assert all(r["commits_per_s"] > 0 and r["p99_ms"] >= r["p50_ms"] for r in found)
    assert f"| {system} | 2 |" in table(found)
    assert not [c for c in _children() if program in c]
