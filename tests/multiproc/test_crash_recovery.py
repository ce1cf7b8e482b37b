"""`kill -9` of a peer daemon in the middle of a commit, holding the write lock
at every holder (issue 7 §1-3).

Three daemons hold one counter. The writer's daemon runs with a fault point
armed (`MAPAPI_FAULTS`, see `mapapi.swarm.faults`), so its commit stops at an exact
moment: every batch staged and nothing applied (`commit.staged`), or applied at
the writer alone (`commit.applied`). The test kills it there with SIGKILL and
checks that

- another peer commits again within the lease + 1 s (here: 6 s);
- no commit is half-applied anywhere: the survivors' histories are identical
  and the killed commit is in neither;
- the killed peer, started again without `--join`, rejoins through the members
  it remembered, catches up and ends with the same history (its own undecided
  commit gone).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time
from pathlib import Path

import pytest

from mapapi import Repository
from mapapi.testing import wait_until

from .conftest import (
    COMMAND_TIMEOUT,
    MAPCTL,
    Daemons,
    holders_of,
    mapctl,
    mapctl_json,
    run_mapctl,
)

pytestmark = pytest.mark.slow

LEASE = 5.0  # the daemons' default write lease
EXIT_NETWORK = 5


def counter(repo: Path, item: str) -> int:
    fields = mapctl_json(repo, "get", "counters", item)
    return int(fields.get("value", 0))  # an int64 is a JSON string; 0 is omitted


def history(repo: Path) -> list[tuple[str, str]]:
    return [(c["commit"], c["message"]) for c in mapctl_json(repo, "log")]


def commit_retrying(repo: Path, message: str) -> None:
    """`mapctl commit` until it goes through; it may fail with exit 5 (a holder
    does not answer yet) only."""
    while True:
        done = run_mapctl(repo, "commit", "-m", message, ok=(0, EXIT_NETWORK))
        if done.returncode == 0:
            return


@pytest.mark.parametrize("point", ["commit.staged", "commit.applied"])
def test_a_writer_killed_mid_commit_holds_nothing_up_and_loses_nothing(
    daemons: Daemons, point: str
) -> None:
    a = daemons.start("a")
    b = daemons.start("b", join=a.join)
    w = daemons.start("w", join=a.join, env={"MAPAPI_FAULTS": f"{point}=pause"})
    mapctl(a.repo, "table", "create", "counters", "--type", "mapapi.v1.Counter")
    chunk = mapctl(a.repo, "chunk", "create", "counters").strip()
    item = mapctl_json(a.repo, "set", "counters", '{"name": "c", "value": 1}')["id"]
    mapctl(a.repo, "commit", "-m", "c = 1")
    for peer in (b, w):
        mapctl(peer.repo, "chunk", "participate", chunk)

    # w's commit stops at the fault point, holding the lock at every holder
    mapctl(w.repo, "set", "counters", item, '{"name": "c", "value": 100}')
    doomed = subprocess.Popen(
        [MAPCTL, "-C", str(w.repo), "commit", "-m", "doomed"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    log = Repository.find(w.repo).log_path

    def paused() -> bool:
        return f"fault point {point} reached" in log.read_text(encoding="utf-8", errors="replace")

    wait_until(paused, timeout=COMMAND_TIMEOUT)
    record = Repository.find(w.repo).running_peer()
    assert record is not None
    os.kill(record.pid, signal.SIGKILL)
    killed = time.monotonic()
    _, err = doomed.communicate(timeout=COMMAND_TIMEOUT)
    assert doomed.returncode == EXIT_NETWORK, err

    # b commits again within the lease + 1 s of the kill
    mapctl(b.repo, "set", "counters", item, '{"name": "c", "value": 2}')
    commit_retrying(b.repo, "c = 2")
    assert time.monotonic() - killed <= LEASE + 1.0

    # no half-applied commit: the survivors agree, and the doomed value is nowhere
    survivors = history(a.repo)
    assert survivors == history(b.repo)
    assert [m for _, m in survivors] == ["c = 2", "c = 1"]
    assert counter(a.repo, item) == counter(b.repo, item) == 2
    holders = set(holders_of(a.repo, chunk))
    assert holders == {a.id, b.id}

    # w restarts on its repository without --join: it rejoins through the members
    # it remembered, holds the chunk again and has exactly the survivors' history
    daemons.restart(w.repo)
    wait_until(lambda: history(w.repo) == survivors, timeout=COMMAND_TIMEOUT)
    mapctl(w.repo, "view", "abort")  # the failed commit left its change staged in the view
    assert counter(w.repo, item) == 2
    wait_until(lambda: w.id in holders_of(a.repo, chunk))
    mapctl(w.repo, "set", "counters", item, '{"name": "c", "value": 3}')
    mapctl(w.repo, "commit", "-m", "c = 3")
    assert history(a.repo) == history(b.repo) == history(w.repo)
    assert json.loads(mapctl(b.repo, "get", "counters", item, "--json"))["value"] == 3
