"""Paper Algorithm 1 across 4 peer processes x 50 increments (issue 3, DESIGN §12).

Four `mapbench.worker` processes on loopback hold one counter chunk; each
runs 50 increments at once (begin, get, update value + 1, commit, retry on
conflict). Afterwards every peer must read a0 + P*N and hold the identical
commit log. The children are driven over their acknowledged line protocol
("run" -> "ran"); the only polling is `wait_until` on the peers' logs, since the
last apply+unlock of a commit may still be on its way to the other holders when
its writer acknowledges.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from mapapi.testing import wait_until
from mapbench.swarm import counter_swarm, run_increments
from mapbench.workers import WorkerProcess, spawn_workers

pytestmark = pytest.mark.slow

PEERS, N, A0 = 4, 50, 7
RUN_DEADLINE = 45.0  # seconds for all increments; the test's own ceiling is pytest's timeout


@pytest.fixture
def workers(tmp_path: Path) -> Iterator[list[WorkerProcess]]:
    """Four started workers; on the way out they are asked to quit, then killed."""
    try:
        with spawn_workers(PEERS, tmp_path) as started:
            print("peers:", [(w.name, w.id, w.address) for w in started])
            yield started
    finally:
        for log in sorted(tmp_path.glob("worker-*.log")):  # shown if the test failed
            text = log.read_text()
            if text:
                print(f"--- {log.name}\n{text[-4000:]}")


def test_four_processes_lose_no_increment(workers: list[WorkerProcess]) -> None:
    _, item = counter_swarm(workers, A0)

    reports, _ = run_increments(workers, N, item, RUN_DEADLINE)

    assert [r["commits"] for r in reports] == [N] * PEERS
    expected = A0 + PEERS * N

    def every_log_complete() -> bool:
        return all(len(w.call("log", "log")["ids"]) == 1 + PEERS * N for w in workers)

    wait_until(every_log_complete, timeout=10.0, interval=0.05)
    assert [w.call("value", "value", item)["value"] for w in workers] == [expected] * PEERS
    logs = [w.call("log", "log")["ids"] for w in workers]
    assert all(log == logs[0] for log in logs[1:])
    assert len(set(logs[0])) == 1 + PEERS * N
