"""A chunk's leader whose event loop is blocked for 10 s (issue 13 §4, the field
scenario where a slow command held a daemon and the others evicted it): three
daemons hold one chunk led by a; a's commit is acknowledged, then a's loop stops
(the fault point `commit.acknowledged=block:10`). Meanwhile b and c elect a new
leader and c commits. When a runs again it follows the new leader instead of
deposing it: its own commit returns, and every peer ends with one history
holding both commits, in the order they were acknowledged.
"""

from __future__ import annotations

import json
import subprocess
import time

import pytest

from .conftest import COMMAND_TIMEOUT, MAPCTL, Daemons, mapctl, mapctl_json

pytestmark = [pytest.mark.slow, pytest.mark.timeout(180)]

BLOCK = 10.0
EXIT_NETWORK = 5


def test_a_blocked_leader_is_replaced_and_follows_when_it_runs_again(daemons: Daemons) -> None:
    a = daemons.start("a", env={"MAPAPI_FAULTS": f"commit.acknowledged=block:{BLOCK:g}"})
    b = daemons.start("b", join=a.join)
    c = daemons.start("c", join=a.join)
    mapctl(a.repo, "table", "create", "pts", "--type", "google.protobuf.Struct")
    chunk = mapctl(a.repo, "chunk", "create", "pts").strip()  # a founds the group, and leads
    for peer in (b, c):
        mapctl(peer.repo, "chunk", "participate", chunk)
    item = mapctl_json(b.repo, "set", "pts", json.dumps({"n": 0}), "--chunk", chunk)["id"]
    mapctl(b.repo, "commit", "-m", "n = 0")  # through a, the leader: no fault on b

    mapctl(a.repo, "set", "pts", item, json.dumps({"n": 1}))
    blocked = subprocess.Popen(
        [MAPCTL, "-C", str(a.repo), "commit", "-m", "n = 1"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    # a's commit is acknowledged (b applied it), and then a's loop blocks
    while "n = 1" not in [e["message"] for e in mapctl_json(b.repo, "log")]:
        assert blocked.poll() is None, blocked.communicate()
    began = time.monotonic()

    # c commits through the new leader while a is blocked (retrying while b and c elect)
    while True:
        mapctl(c.repo, "set", "pts", item, json.dumps({"n": 2}))
        done = subprocess.run(
            [MAPCTL, "-C", str(c.repo), "commit", "-m", "n = 2"],
            capture_output=True,
            text=True,
            timeout=COMMAND_TIMEOUT,
            check=False,
        )
        if done.returncode == 0:
            break
        assert done.returncode == EXIT_NETWORK, done.stderr
        mapctl(c.repo, "view", "abort")
    committed_during_block = time.monotonic() - began < BLOCK

    _, err = blocked.communicate(timeout=COMMAND_TIMEOUT + BLOCK)
    assert blocked.returncode == 0, err  # acknowledged before the block: it stands
    assert committed_during_block
    messages = {}
    for peer in (a, b, c):
        while True:  # a catches up from the new leader once it runs again
            entries = mapctl_json(peer.repo, "log")
            messages[peer.repo.name] = [e["message"] for e in reversed(entries)]
            if len(entries) >= 3 or time.monotonic() - began > 60:
                break
    assert set(map(tuple, messages.values())) == {("n = 0", "n = 1", "n = 2")}, messages
    assert {mapctl_json(p.repo, "get", "pts", item)["n"] for p in (a, b, c)} == {2}
    assert "blocking the event loop" in (a.repo / ".mapapi" / "peer.log").read_text()
