"""Lookup across peer processes (issue 4 §5): a peer that never saw a chunk finds
it by id and by box through the swarm's Chord ring, and loads it; a peer whose
spatial index differs is refused.

Every step is a real `mapctl` process talking to real peer daemons on
127.0.0.1 (as in test_daemons.py).
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from .conftest import COMMAND_TIMEOUT, MAPCTL, Daemons, mapctl, mapctl_json

pytestmark = pytest.mark.slow


def rooms(repo: Path, *boxes: list[float]) -> str:
    """Create a Struct table "rooms" and a chunk of rooms with these boxes,
    committed through the daemon; returns the chunk id."""
    mapctl(repo, "table", "create", "rooms", "--type", "google.protobuf.Struct")
    chunk = mapctl(repo, "chunk", "create", "rooms").strip()
    for box in boxes:
        mapctl(repo, "set", "rooms", "--chunk", chunk, json.dumps({"bbox": box}))
    mapctl(repo, "commit", "-m", f"{len(boxes)} rooms")
    return chunk


def test_a_peer_that_never_saw_a_chunk_finds_it_by_id_and_by_box(daemons: Daemons) -> None:
    a = daemons.start("a")
    b = daemons.start("b", join=a.join)
    c = daemons.start("c", join=b.join)
    hall = rooms(a.repo, [0, 0, 0, 20, 4, 3], [20, 0, 0, 24, 30, 3])
    lab = rooms(b.repo, [-300, 200, 0, -280, 230, 4])

    # by id: c has never heard of a's chunk, the ring knows who holds it
    joined = mapctl_json(c.repo, "chunk", "participate", hall)
    assert (joined["chunk"], joined["items"]) == (hall, 2)
    assert set(joined["holders"]) == {a.id, c.id}

    # by box: the query lists b's lab with its holder, without loading it
    found = mapctl_json(c.repo, "query-bbox", "-310", "190", "-1", "-290", "210", "1")
    assert found == {
        "results": [
            {
                "ref": lab,
                "kind": "chunk",
                "chunk": lab,
                "table": "rooms",
                "missions": [],
                "bbox": [-300.0, 200.0, 0.0, -280.0, 230.0, 4.0],
                "holders": [{"id": b.id, "name": "b", "address": b.address}],
                "held": False,
            }
        ]
    }
    assert lab not in {ch["id"] for ch in mapctl_json(c.repo, "chunk", "list")["chunks"]}

    # a box over both finds both; --load fetches the one c lacks
    both = ["-1000", "-1000", "-10", "1000", "1000", "10"]
    loaded = mapctl_json(c.repo, "query-bbox", *both, "--load")["results"]
    assert [(r["chunk"], r["held"]) for r in loaded] == sorted([(hall, True), (lab, True)])
    held = {ch["id"]: ch["items"] for ch in mapctl_json(c.repo, "chunk", "list")["chunks"]}
    assert held == {hall: 2, lab: 1}
    assert mapctl_json(c.repo, "ls", "rooms", "--chunk", lab)["items"][0]["data"] == {
        "bbox": [-300.0, 200.0, 0.0, -280.0, 230.0, 4.0]
    }

    # nothing there: an empty result, not an error
    nowhere = ["500", "500", "0", "510", "510", "1"]
    assert mapctl_json(a.repo, "query-bbox", *nowhere) == {"results": []}


def test_a_peer_with_another_spatial_index_is_refused(daemons: Daemons) -> None:
    a = daemons.start("a")
    other = daemons.root / "other"
    subprocess.run(
        [MAPCTL, "init", str(other), "--cells", "8", "8", "1"],
        check=True,
        capture_output=True,
        timeout=COMMAND_TIMEOUT,
    )
    daemons.adopt(other)
    refused = subprocess.run(
        [MAPCTL, "-C", str(other), "peer", "start", "--detach", "--join", a.join],
        capture_output=True,
        text=True,
        timeout=COMMAND_TIMEOUT,
        check=False,
    )
    assert refused.returncode != 0
    assert "spatial index differs" in refused.stderr
    assert mapctl_json(a.repo, "peers") == {"peers": []}
