"""`kill -9` of a peer daemon in the middle of a commit through the chunks' Raft
logs (issue 13, DESIGN §13).

Three daemons hold the counters. The writer's daemon runs with a fault point
armed (`MAPAPI_FAULTS`, see `mapapi.swarm.faults`), so its commit stops at an exact
moment: the chunk's log took it (`commit.acknowledged`: a majority of voters hold
it, the writer has not answered), or every chunk of a two-chunk transaction holds
its prepare and no decision is proposed (`commit.prepared`). The test kills it
there with SIGKILL and checks that

- another peer commits again (at once after an acknowledged commit; after the
  chunks' leaders settled the abandoned transaction from its first chunk's log);
- one history: the survivors' histories are identical; the acknowledged commit
  is in them, the abandoned transaction in neither, whole or in part;
- the killed peer, started again without `--join`, rejoins through the members
  it remembered, catches up and ends with the same history.
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

SETTLED = 15.0 + 5.0  # swarm.tx_recovery.RECOVER_AFTER, and a few sweeps and elections
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


@pytest.mark.parametrize("point", ["commit.acknowledged", "commit.prepared"])
def test_a_writer_killed_mid_commit_holds_nothing_up_and_loses_nothing(
    daemons: Daemons, point: str
) -> None:
    a = daemons.start("a")
    b = daemons.start("b", join=a.join)
    w = daemons.start("w", join=a.join, env={"MAPAPI_FAULTS": f"{point}=pause"})
    mapctl(a.repo, "table", "create", "counters", "--type", "mapapi.v1.Counter")
    chunks = [mapctl(a.repo, "chunk", "create", "counters").strip() for _ in range(2)]
    items = [
        mapctl_json(a.repo, "set", "counters", '{"name": "c", "value": 1}', "--chunk", c)["id"]
        for c in chunks
    ]
    mapctl(a.repo, "commit", "-m", "c = 1")
    for peer in (b, w):
        for chunk in chunks:
            mapctl(peer.repo, "chunk", "participate", chunk)

    # w's commit stops at the fault point: one chunk acknowledged, or both prepared
    touched = items[:1] if point == "commit.acknowledged" else items
    for item in touched:
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

    # b commits again to every chunk w's commit touched (two of three voters live)
    for item in touched:
        mapctl(b.repo, "set", "counters", item, '{"name": "c", "value": 2}')
    commit_retrying(b.repo, "c = 2")
    assert time.monotonic() - killed <= (SETTLED if point == "commit.prepared" else 10.0)

    # one history: acknowledged means kept; the abandoned transaction is nowhere
    kept = ["c = 2", "doomed", "c = 1"] if point == "commit.acknowledged" else ["c = 2", "c = 1"]
    wait_until(lambda: history(a.repo) == history(b.repo), timeout=COMMAND_TIMEOUT)
    survivors = history(a.repo)
    assert [m for _, m in survivors] == kept
    for item in touched:
        assert counter(a.repo, item) == counter(b.repo, item) == 2
    for chunk in chunks:
        assert w.id in holders_of(a.repo, chunk)  # a member until removed, 30 s after

    # w restarts on its repository without --join: it rejoins through the members
    # it remembered, catches up, and has exactly the survivors' history
    daemons.restart(w.repo)
    wait_until(lambda: history(w.repo) == survivors, timeout=COMMAND_TIMEOUT)
    mapctl(w.repo, "view", "abort")  # the failed commit left its change staged in the view
    for item in touched:
        assert counter(w.repo, item) == 2
    mapctl(w.repo, "set", "counters", items[0], '{"name": "c", "value": 3}')
    mapctl(w.repo, "commit", "-m", "c = 3")
    wait_until(lambda: history(a.repo) == history(b.repo) == history(w.repo))
    assert json.loads(mapctl(b.repo, "get", "counters", items[0], "--json"))["value"] == 3
