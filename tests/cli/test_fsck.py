"""`mapctl fsck`: the store, every payload and every chain, checked and reported."""

from __future__ import annotations

import sqlite3
from pathlib import Path

from mapapi import Peer
from mapapi.core.change import Change, Op
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId
from mapapi.core.proposal import Proposal
from mapapi.service.fsck import check_repository
from mapapi.swarm.apply import apply_proposal
from tests.cli.conftest import Mapctl


def test_a_sound_repository_passes(points: Mapctl) -> None:
    points.insert({"x": 1.0})
    points.commit()
    report = points.json("fsck")
    assert report["ok"] is True
    assert report["payloads"]["checked"] > 0
    assert report["integrity"] == []


def test_a_payload_that_no_longer_parses_fails_with_exit_1(points: Mapctl) -> None:
    points.insert({"x": 1.0})
    points.commit()
    con = sqlite3.connect(points.repo / ".mapapi" / "store.sqlite")
    (item,) = con.execute("SELECT item_id FROM revisions LIMIT 1").fetchone()
    con.execute("UPDATE revisions SET data = x'ffffffff' WHERE item_id = ?", (item,))
    con.commit()
    con.close()
    outcome = points.main("fsck")
    assert outcome.code == 1
    assert item.hex() in outcome.out


def test_a_chain_that_no_longer_matches_is_reported(tmp_path: Path) -> None:
    peer = Peer.in_memory()
    store = peer.store
    chunk = ChunkId.new()
    store.add_table("t", "google.protobuf.Struct")
    store.add_chunk(chunk, "t")
    store.raft_save(chunk, hard=(1, 0, 1))
    item = ItemId.new()
    change = Change(Op.INSERT, "t", item, chunk, b"")
    proposal = Proposal(CommitId.new(), 1, PeerId.new(), "a", "", "m", 0, "snapshot", (change,))
    with store.exclusive():
        apply_proposal(store, chunk, proposal)
    assert check_repository(peer)["chains"] == {"checked": 1, "problems": []}
    store.drop_chunk(chunk)  # its commit's revisions are gone; the chain remembers them
    store.add_chunk(chunk, "t")
    report = check_repository(peer)
    assert report["ok"] is False
    assert "no longer matches" in report["chains"]["problems"][0]
