"""Secure peer daemons, each its own process, through the CLI (issue 7 §6).

Two secure repositories trust each other's keys; the second daemon joins the
first through the `join` string `peer start --detach --json` printed, which
carries the first one's key; they replicate a chunk. A daemon whose key is not
trusted, and an open one, are refused with a message that says why; a fourth
secure repository, trusted in advance, clones the swarm.
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from mapapi.net.security import split_address

from .conftest import COMMAND_TIMEOUT, MAPCTL, Daemons, mapctl, mapctl_json, run_mapctl

pytestmark = pytest.mark.slow

EXIT_NETWORK = 5


def init(path: Path, *flags: str) -> Path:
    subprocess.run(
        [MAPCTL, "init", str(path), *flags],
        check=True,
        capture_output=True,
        timeout=COMMAND_TIMEOUT,
    )
    return path


def key(repo: Path) -> str:
    return mapctl(repo, "key", "show").strip()


def trust(repo: Path, *others: Path) -> None:
    mapctl(repo, "trust", "add", *(key(o) for o in others))


def test_two_secure_daemons_form_a_swarm_through_the_join_string(
    daemons: Daemons, tmp_path: Path
) -> None:
    a, b = init(tmp_path / "a", "--secure"), init(tmp_path / "b", "--secure")
    trust(a, b)
    trust(b, a)
    daemons.adopt(a)
    daemons.adopt(b)
    first = mapctl_json(a, "peer", "start", "--detach")
    assert split_address(first["join"])[1] == bytes.fromhex(key(a))
    second = mapctl_json(b, "peer", "start", "--detach", "--join", first["join"])
    assert [p["id"] for p in mapctl_json(a, "peers")["peers"]] == [second["id"]]
    assert [p["address"] for p in mapctl_json(b, "peers")["peers"]] == [first["address"]]

    mapctl(a, "table", "create", "pts", "--type", "google.protobuf.Struct")
    chunk = mapctl(a, "chunk", "create", "pts").strip()
    item = mapctl_json(a, "set", "pts", json.dumps({"door": 1}))["id"]
    mapctl(a, "commit", "-m", "a door")
    assert mapctl_json(b, "chunk", "participate", chunk)["items"] == 1
    mapctl(b, "set", "pts", item, json.dumps({"door": 2}))
    mapctl(b, "commit", "-m", "b moves it")
    for repo in (a, b):
        assert mapctl_json(repo, "get", "pts", item) == {"door": 2}

    # a secure peer a does not trust: refused, and told which key to trust where
    c = init(tmp_path / "c", "--secure")
    trust(c, a)
    daemons.adopt(c)
    refused = run_mapctl(
        c, "peer", "start", "--detach", "--join", first["join"], ok=(EXIT_NETWORK,)
    )
    assert f"refused this peer's key {key(c)}" in refused.stderr
    assert f"mapctl trust add {key(c)}" in refused.stderr

    # an open peer: refused, and told the swarm is secure
    d = init(tmp_path / "d")
    daemons.adopt(d)
    mixed = run_mapctl(d, "peer", "start", "--detach", "--join", first["join"], ok=(EXIT_NETWORK,))
    assert "is a secure swarm and this peer is open" in mixed.stderr

    # a peer the swarm trusts in advance clones it through the same join string
    e = init(tmp_path / "e", "--secure")
    trust(e, a, b)
    trust(a, e)
    trust(b, e)
    daemons.adopt(e)
    cloned = mapctl_json(e, "clone", first["join"], str(e))
    assert [c["chunk"] for c in cloned["chunks"]] == [chunk]
    assert mapctl_json(e, "get", "pts", item) == {"door": 2}
