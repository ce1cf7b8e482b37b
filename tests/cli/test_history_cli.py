"""Verifiable history from the command line (issue 18 §3), the probe's cases: a byte
flipped in a payload, a store rolled back behind its high-water mark (an older copy
of its files put back, or a damaged write-ahead log), and two holders whose
histories of a chunk differ (real peer processes: peer.log, `peer status`, then an
offline `fsck`)."""

from __future__ import annotations

import asyncio
import json
import shutil
import sqlite3
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import pytest
from google.protobuf.struct_pb2 import Struct

from mapapi import Peer, Repository
from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId
from mapapi.store import SqliteStore, mark
from mapapi.testing import wait_until
from tests.cli.conftest import STRUCT, Mapctl
from tests.multiproc.conftest import Daemons, mapctl, mapctl_json, run_mapctl

WAIT = 30.0  # seconds for the holders' next comparison (every 5 s) and the daemons


def store_files(repo: Path) -> list[Path]:
    """The store's database files: the file, its write-ahead log and its index."""
    return sorted((repo / ".mapapi").glob("store.sqlite*"))


def commit_points(points: Mapctl, n: int) -> None:
    for i in range(n):
        points.insert({"x": float(i)})
        points.commit(f"point {i}")


def test_a_flipped_byte_in_a_payload_that_still_parses_is_named(points: Mapctl) -> None:
    points.insert({"x": 1.0})
    record = points.commit("one point")
    con = sqlite3.connect(points.repo / ".mapapi" / "store.sqlite")
    (data,) = con.execute("SELECT data FROM revisions").fetchone()
    flipped = bytes(data[:-1]) + bytes([data[-1] ^ 0x01])  # the double's last byte: 1.0 no more
    con.execute("UPDATE revisions SET data = ?", (flipped,))
    con.commit()
    con.close()
    outcome = points.main("fsck")
    assert outcome.code == 1
    assert f"commit {record['commit'][:8]} no longer matches its link" in outcome.out
    report = json.loads(points.main("fsck", "--json").out)
    assert report["ok"] is False
    assert report["payloads"]["bad"] == []  # it parses: only the chain tells
    assert len(report["chains"]["problems"]) == 1


@pytest.fixture
def reader(points: Mapctl) -> Iterator[sqlite3.Connection]:
    """A connection held open, as a running peer holds one: the commits stay in the
    write-ahead log (the last connection to close would checkpoint and delete it)."""
    con = sqlite3.connect(points.repo / ".mapapi" / "store.sqlite")
    con.execute("SELECT COUNT(*) FROM commits").fetchone()
    yield con
    con.close()


@pytest.mark.parametrize("damage", ["older copy", "damaged log"])
def test_a_rolled_back_store_is_reported_until_accepted(
    points: Mapctl, reader: sqlite3.Connection, tmp_path: Path, damage: str
) -> None:
    assert reader is not None
    commit_points(points, 3)
    copy = tmp_path / "copy"
    copy.mkdir()
    if damage == "older copy":  # mid-way, as a backup taken while the peer ran
        for f in store_files(points.repo):
            shutil.copy2(f, copy / f.name)
    commit_points(points, 5)
    if damage == "damaged log":  # every commit is in the log: damage it past the 3rd
        for f in store_files(points.repo):
            shutil.copy2(f, copy / f.name)
        wal = copy / "store.sqlite-wal"
        raw = bytearray(wal.read_bytes())
        middle = len(raw) * 5 // 8
        raw[middle : middle + 64] = bytes(64)
        wal.write_bytes(bytes(raw))
    reader.close()
    for f in store_files(points.repo):
        f.unlink()
    for f in copy.iterdir():
        shutil.copy2(f, points.repo / ".mapapi" / f.name)

    outcome = points.main("fsck")
    assert outcome.code == 1
    assert "the store is behind what it had recorded" in outcome.out
    report = json.loads(points.main("fsck", "--json").out)
    missing = report["rollback"]["missing"]
    assert report["ok"] is False
    assert 1 <= missing <= 5
    assert f"{missing} commit(s) missing (rolled back" in report["rollback"]["problems"][0]

    commit_points(points, 1)  # the first write records it: it is not forgotten
    assert json.loads(points.main("fsck", "--json").out)["rollback"]["missing"] == missing
    accepted = json.loads(points.main("fsck", "--accept", "--json").out)
    assert accepted["ok"] is True
    assert points.main("fsck").code == 0


def test_a_peer_that_starts_behind_its_mark_says_so(
    points: Mapctl, caplog: pytest.LogCaptureFixture
) -> None:
    commit_points(points, 2)
    path = points.repo / ".mapapi" / "store.mark"
    kept = mark.read(path)
    assert kept is not None
    mark.write(path, replace(kept, applied=kept.applied + 4))  # as after a rollback

    async def start() -> None:
        peer = Peer.open(points.repo)
        try:
            await peer.start()
        finally:
            await peer.close()

    asyncio.run(start())
    errors = [r.getMessage() for r in caplog.records if r.levelname == "ERROR"]
    assert any("4 commit(s) missing (rolled back" in m for m in errors)


# -- two holders, two histories: real peer processes -----------------------------------
def inject(repo: Path, chunk: str) -> None:
    """A commit written straight into the store of `repo`'s running peer, which no
    other holder sees (the forged commit of issue 18's probe)."""
    store = SqliteStore(repo / ".mapapi" / "store.sqlite")
    try:
        time = store.clock() + 1
        author = PeerId(Repository.find(repo).config.peer_id)
        record = CommitRecord(CommitId.new(), time, author, "forged", (ChunkId(chunk),))
        payload = Struct()
        payload.update({"x": 99.0})
        table = store.chunk_table(ChunkId(chunk))
        revision = Revision(
            ItemId.new(),
            table,
            ChunkId(chunk),
            payload.SerializeToString(),
            time,
            time,
            False,
            author,
            record.id,
        )
        store.apply_commit(record, [revision])
    finally:
        store.close()


@pytest.mark.slow
def test_two_holders_with_different_histories_are_reported(tmp_path: Path) -> None:
    daemons = Daemons(tmp_path)
    try:
        a = daemons.start("a")
        b = daemons.start("b", join=a.join)
        mapctl(a.repo, "table", "create", "pts", "--type", STRUCT)
        chunk = mapctl_json(a.repo, "chunk", "create", "pts")["id"]
        mapctl(a.repo, "set", "pts", '{"x": 1.0}')
        mapctl(a.repo, "commit", "-m", "first")
        mapctl(b.repo, "chunk", "participate", chunk)
        inject(b.repo, chunk)
        mapctl(a.repo, "set", "pts", '{"x": 2.0}')
        mapctl(a.repo, "commit", "-m", "second")  # reaches b after its forged commit

        def both_see_it() -> bool:
            return all(mapctl_json(d.repo, "peer", "status")["diverged"] for d in (a, b))

        wait_until(both_see_it, timeout=WAIT, interval=0.5)
        for here, there in ((a, b), (b, a)):
            (found,) = mapctl_json(here.repo, "peer", "status")["diverged"]
            assert (found["chunk"], found["peer"], found["commit"]) == (chunk, there.id, 2)
            assert "differs from peer" in mapctl(here.repo, "peer", "status")
            log = (here.repo / ".mapapi" / "peer.log").read_text()
            assert f"ERROR mapapi.swarm.chain_watch: chunk {chunk[:8]}: commit 2" in log
        for d in (a, b):
            mapctl(d.repo, "peer", "stop")
        for d in (a, b):  # offline: the store remembers
            done = run_mapctl(d.repo, "fsck", "--json", ok=(1,))
            assert json.loads(done.stdout)["diverged"][0]["chunk"] == chunk
    finally:
        daemons.cleanup()
