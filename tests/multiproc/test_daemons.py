"""Three peer daemons, each its own process, replicate a chunk through the CLI.

Every step is a real `mapctl` process: `peer start --detach --json` starts each
daemon (in a new session, real sockets on 127.0.0.1, port 0), the others join
the first through the printed `join` string; then `set`/`commit`, `chunk
participate`, `ls`/`log`/`peers --json` go through each repository's daemon.
Every peer must end with the same items and the same log. `clone` makes a
fourth peer from an address. A fixture stops every daemon afterwards and kills
whatever does not stop (DESIGN §9; issue 3 §2).
"""

from __future__ import annotations

import json
import subprocess

import pytest

from mapapi import Repository

from .conftest import COMMAND_TIMEOUT, MAPCTL, Daemons, mapctl, mapctl_json

pytestmark = pytest.mark.slow

EXIT_CONFLICT = 3


def test_three_daemons_replicate_a_chunk_and_see_each_others_commits(daemons: Daemons) -> None:
    a = daemons.start("a")
    b = daemons.start("b", join=a.join)
    c = daemons.start("c", join=a.join)
    peers = [a, b, c]

    # membership: every peer learned the whole swarm from the one it joined through
    for peer in peers:
        listed = mapctl_json(peer.repo, "peers")["peers"]
        assert {p["id"] for p in listed} == {q.id for q in peers} - {peer.id}
        assert {p["address"] for p in listed} == {q.address for q in peers} - {peer.address}
        for row in listed:
            assert set(row) == {"id", "address", "name", "last_seen", "shared_chunks"}
            assert row["shared_chunks"] == []

    # a makes the table and chunk and commits three items through its daemon
    mapctl(a.repo, "table", "create", "pts", "--type", "google.protobuf.Struct")
    chunk = mapctl(a.repo, "chunk", "create", "pts").strip()
    items = [mapctl_json(a.repo, "set", "pts", json.dumps({"n": n}))["id"] for n in range(3)]
    first = mapctl_json(a.repo, "commit", "-m", "three points")
    assert first["commit"] is not None

    # b and c participate: the full chunk with its history
    for peer in (b, c):
        joined = mapctl_json(peer.repo, "chunk", "participate", chunk)
        assert joined["chunk"] == chunk
        assert joined["table"] == "pts"
        assert joined["items"] == 3
    holders = {a.id, b.id, c.id}
    assert set(mapctl_json(a.repo, "chunk", "participate", chunk)["holders"]) == holders

    # each peer commits through its own daemon
    mapctl(b.repo, "set", "pts", items[0], json.dumps({"n": 10, "by": "b"}))
    mapctl(b.repo, "commit", "-m", "b edits 0")
    added = mapctl_json(c.repo, "set", "pts", json.dumps({"n": 3, "by": "c"}))["id"]
    mapctl(c.repo, "commit", "-m", "c adds 3")
    mapctl(a.repo, "rm", "pts", items[1])
    mapctl(a.repo, "commit", "-m", "a removes 1")

    # a conflict across peers travels through the daemons as exit 3
    for peer in (b, c):
        mapctl(peer.repo, "view", "open", view="race")
    mapctl(b.repo, "set", "pts", items[2], '{"n": 20}', view="race")
    mapctl(c.repo, "set", "pts", items[2], '{"n": 30}', view="race")
    mapctl(b.repo, "commit", "-m", "b wins the race", view="race")
    mapctl(c.repo, "commit", "-m", "c loses", view="race", ok=(EXIT_CONFLICT,))
    conflicts = mapctl_json(c.repo, "diff", view="race")["conflicts"]
    assert [(x["id"], x["theirs"], x["ours"]) for x in conflicts] == [
        (items[2], {"n": 20.0}, {"n": 30.0})
    ]
    mapctl(c.repo, "view", "abort", view="race")

    # every replica agrees
    expected = sorted(
        [
            {"id": items[0], "data": {"n": 10.0, "by": "b"}},
            {"id": items[2], "data": {"n": 20.0}},
            {"id": added, "data": {"n": 3.0, "by": "c"}},
        ],
        key=lambda r: r["id"],
    )
    logs = []
    for peer in peers:
        listed = mapctl_json(peer.repo, "ls", "pts")["items"]
        assert sorted(listed, key=lambda r: r["id"]) == expected, peer.repo.name
        logs.append(mapctl_json(peer.repo, "log"))
    assert logs[0] == logs[1] == logs[2]
    assert [r["message"] for r in logs[0]] == [
        "b wins the race",
        "a removes 1",
        "c adds 3",
        "b edits 0",
        "three points",
    ]
    assert [r["author"] for r in logs[0]] == [b.id, a.id, c.id, b.id, a.id]

    # everyone now shares the chunk with everyone
    for peer in peers:
        listed = mapctl_json(peer.repo, "peers")["peers"]
        assert all(row["shared_chunks"] == [chunk] for row in listed)

    # a graceful stop says goodbye: the others forget the peer
    stopped = mapctl_json(c.repo, "peer", "stop")
    assert stopped == {"stopped": True, "pid": stopped["pid"], "id": c.id}
    assert Repository.find(c.repo).read_peer_record() is None
    assert {p["id"] for p in mapctl_json(a.repo, "peers")["peers"]} == {b.id}
    for peer in (a, b):
        assert mapctl_json(peer.repo, "peer", "stop")["stopped"] is True
    for peer in peers:
        assert Repository.find(peer.repo).running_peer() is None
        assert mapctl_json(peer.repo, "peer", "status") == {"running": False}
    # alone again, each repository still reads its replica
    assert sorted(mapctl_json(c.repo, "ls", "pts")["items"], key=lambda r: r["id"]) == expected


def test_clone_joins_and_participates_in_the_chosen_chunks(daemons: Daemons) -> None:
    a = daemons.start("a")
    mapctl(a.repo, "table", "create", "pts", "--type", "google.protobuf.Struct")
    mapctl(a.repo, "table", "create", "poses", "--type", "google.protobuf.Struct")
    pts = mapctl(a.repo, "chunk", "create", "pts").strip()
    poses = mapctl(a.repo, "chunk", "create", "poses").strip()
    mapctl(a.repo, "set", "pts", '{"x": 1}')
    mapctl(a.repo, "set", "poses", '{"yaw": 0.5}')
    mapctl(a.repo, "commit", "-m", "one of each")

    everything = daemons.root / "clone-all"
    daemons.adopt(everything)
    cloned = mapctl_json(daemons.root, "clone", a.join, str(everything), "--chunks", "all")
    assert set(cloned) == {"path", "id", "address", "join", "chunks"}
    assert cloned["path"] == str(everything.resolve())
    assert {c["chunk"] for c in cloned["chunks"]} == {pts, poses}
    for table in ("pts", "poses"):
        assert mapctl_json(everything, "ls", table) == mapctl_json(a.repo, "ls", table)
    assert mapctl_json(everything, "log") == mapctl_json(a.repo, "log")
    assert [p["id"] for p in mapctl_json(everything, "peers")["peers"]] == [a.id]

    nothing = daemons.root / "clone-none"
    daemons.adopt(nothing)
    empty = mapctl_json(daemons.root, "clone", a.join, str(nothing), "--chunks", "none")
    assert empty["chunks"] == []
    assert mapctl_json(nothing, "chunk", "list") == {"chunks": []}

    # lookup by peer: a's chunks, asked through nothing's daemon and, from a
    # repository with no daemon, over a connection of the command's own
    held = sorted([(pts, "pts", 1), (poses, "poses", 1)])
    listed = mapctl_json(nothing, "chunk", "list", "--peer", a.address)
    assert sorted((c["id"], c["table"], c["items"]) for c in listed["chunks"]) == held
    offline = daemons.root / "offline"
    subprocess.run(
        [MAPCTL, "init", str(offline)], check=True, capture_output=True, timeout=COMMAND_TIMEOUT
    )
    listed = mapctl_json(offline, "chunk", "list", "--peer", a.address, "--table", "pts")
    assert listed == {"chunks": [{"id": pts, "table": "pts", "items": 1}]}

    one = daemons.root / "clone-one"
    daemons.adopt(one)
    picked = mapctl_json(daemons.root, "clone", a.join, str(one), "--chunks", poses)
    assert [c["chunk"] for c in picked["chunks"]] == [poses]
    assert [c["id"] for c in mapctl_json(one, "chunk", "list")["chunks"]] == [poses]
    # a commit on the clone reaches the original
    mapctl(one, "set", "poses", '{"yaw": 1.5}')
    mapctl(one, "commit", "-m", "from the clone")
    assert mapctl_json(a.repo, "log")[0]["message"] == "from the clone"

    # a clone from an address nobody listens on leaves nothing behind
    refused = subprocess.run(
        [MAPCTL, "clone", "tcp://127.0.0.1:9", str(daemons.root / "nowhere")],
        capture_output=True,
        text=True,
        timeout=COMMAND_TIMEOUT * 2,
        check=False,
    )
    assert refused.returncode == 5, refused.stderr
    assert "before it served" in refused.stderr
    assert not (daemons.root / "nowhere").exists()
