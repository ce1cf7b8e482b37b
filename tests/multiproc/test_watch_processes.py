"""`mapctl watch` against real peer daemons (issue 6 §3): a watcher process
streams the changes committed in its region by another peer, as JSON lines,
and exits after --count; --timeout, a region outside the index and a stopped
peer give clear errors and non-zero exits."""

from __future__ import annotations

import json
import selectors
import subprocess

import pytest

from .conftest import COMMAND_TIMEOUT, MAPCTL, Daemons, mapctl, run_mapctl

pytestmark = pytest.mark.slow


def first_stderr_line(proc: subprocess.Popen[str], timeout: float) -> str:
    """The first line the process writes to stderr (it says when it subscribed)."""
    assert proc.stderr is not None
    with selectors.DefaultSelector() as selector:
        selector.register(proc.stderr, selectors.EVENT_READ)
        assert selector.select(timeout), "the watcher said nothing"
    return proc.stderr.readline()


def test_watch_streams_the_changes_in_its_region(daemons: Daemons) -> None:
    a = daemons.start("a")
    b = daemons.start("b", join=a.join)
    mapctl(a.repo, "table", "create", "rooms", "--type", "google.protobuf.Struct")
    mapctl(a.repo, "chunk", "create", "rooms")
    region = ["--bbox", "-5", "-5", "-1", "10", "10", "3"]
    filters = ["--where", "kind=door", "--count", "2", "--timeout", "30", "--json"]
    watcher = subprocess.Popen(
        [MAPCTL, "-C", str(b.repo), "watch", *region, *filters],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert first_stderr_line(watcher, COMMAND_TIMEOUT).startswith("watching -5 -5 -1 10 10 3")
        rows = [
            ({"kind": "door", "bbox": [100, 100, 0, 101, 101, 1]}, "far door"),
            ({"kind": "window", "bbox": [1, 1, 0, 2, 2, 1]}, "near window"),
            ({"kind": "door", "bbox": [1, 1, 0, 2, 2, 1]}, "near door"),
            ({"kind": "door", "bbox": [-4, 1, 0, -3, 2, 1]}, "another near door"),
            ({"kind": "door", "bbox": [0, 0, 0, 1, 1, 1]}, "after the count"),
        ]
        for data, message in rows:
            mapctl(a.repo, "set", "rooms", json.dumps(data))
            mapctl(a.repo, "commit", "-m", message)
        out, err = watcher.communicate(timeout=COMMAND_TIMEOUT)
    finally:
        watcher.kill()
        watcher.wait()
    assert watcher.returncode == 0, err
    changes = [json.loads(line) for line in out.splitlines()]
    assert [(c["message"], c["kind"], c["table"]) for c in changes] == [
        ("near door", "inserted", "rooms"),
        ("another near door", "inserted", "rooms"),
    ]
    assert changes[0]["data"] == {"kind": "door", "bbox": [1.0, 1.0, 0.0, 2.0, 2.0, 1.0]}
    assert changes[0]["author"] == a.id


def test_watch_errors(daemons: Daemons) -> None:
    a = daemons.start("a")
    nothing = run_mapctl(a.repo, "watch", "--timeout", "0.5", ok=(1,))
    assert "0 change(s) arrived in 0.5 s" in nothing.stderr
    outside = ["--bbox", "5000", "5000", "0", "6000", "6000", "1"]
    far = run_mapctl(a.repo, "watch", *outside, "--timeout", "1", ok=(2,))
    assert "outside the spatial index" in far.stderr
    mapctl(a.repo, "peer", "stop")
    alone = run_mapctl(a.repo, "watch", "--timeout", "1", ok=(5,))
    assert "no peer runs on this repository" in alone.stderr
