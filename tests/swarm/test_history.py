"""Verifiable history across holders (issue 18 §3): every commit on the lock path
extends the same hash chain at the writer and at every holder, a chunk fetched by
participation arrives with the sender's chain, and two holders with different
histories of a chunk say so: an error in the log, a record in the store that
`peer status` and `fsck` show, at once after a rejoin."""

from __future__ import annotations

import logging
import sqlite3

import pytest

from mapapi import Peer
from mapapi.core.errors import CorruptRepoError
from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, CommitId, ItemId
from mapapi.service.fsck import check_repository
from mapapi.service.transfer_ops import SwarmOperations
from mapapi.store import SqliteStore
from mapapi.swarm.chain_check import check_chain

from .conftest import TABLE, Counter, MakeSwarm, counter_chunk, increment, log_ids, net, share


def inject(peer: Peer, chunk: ChunkId) -> CommitRecord:
    """A commit written straight into one replica's store, which no other holder
    sees (as the forged commit of issue 18's probe was)."""
    time = peer.store.clock() + 1
    record = CommitRecord(CommitId.new(), time, peer.id, "behind the swarm's back", (chunk,))
    data = Counter(name="x", value=7).SerializeToString()
    revision = Revision(ItemId.new(), TABLE, chunk, data, time, time, False, peer.id, record.id)
    peer.store.apply_commit(record, [revision])
    peer.clock.advance_to(time)  # later commits are stamped past it, as a real one's
    return record


def chains(peers: list[Peer], chunk: ChunkId) -> list[list[tuple[CommitId, bytes]]]:
    return [p.store.chain_links(chunk) for p in peers]


async def test_every_holder_links_every_commit_alike(swarm: MakeSwarm) -> None:
    peers = await swarm(3)
    chunk, item = await counter_chunk(peers[0])
    await share(chunk, peers[1:])
    for peer in peers:  # the writer and the holders, in turn
        await increment(peer, [(TABLE, item)])
    for peer in peers:
        await log_ids(peer)  # no writer holds the chunk: every apply has landed
    first, *others = chains(peers, chunk)
    assert len(first) == 4  # the chunk's first commit and the three increments
    assert all(other == first for other in others)
    assert all(check_chain(p.store, chunk) == [] for p in peers)


async def test_a_fetched_chunk_arrives_with_the_senders_chain(swarm: MakeSwarm) -> None:
    a, b = await swarm(2)
    chunk, item = await counter_chunk(a)
    for _ in range(3):
        await increment(a, [(TABLE, item)])
    await b.participate(chunk)
    assert b.store.chain_links(chunk) == a.store.chain_links(chunk)
    await increment(b, [(TABLE, item)])
    await log_ids(a)
    assert a.store.chain_links(chunk) == b.store.chain_links(chunk)


async def test_holders_with_different_histories_say_so(
    swarm: MakeSwarm, caplog: pytest.LogCaptureFixture
) -> None:
    a, b = await swarm(2)
    chunk, item = await counter_chunk(a)
    await share(chunk, [b])
    forged = inject(b, chunk)
    await increment(a, [(TABLE, item)])  # reaches b after its forged commit
    await log_ids(b)
    with caplog.at_level(logging.ERROR, logger="mapapi.swarm.chain_watch"):
        await net(a).chains.compare()
    for peer, other in ((a, b), (b, a)):
        (found,) = peer.store.divergences()
        assert (found.chunk, found.peer, found.position) == (chunk, other.id, 2)
        status = await SwarmOperations(peer).peer_status()
        assert [d["chunk"] for d in status["diverged"]] == [chunk]
        report = check_repository(peer)
        assert report["ok"] is False
        assert "differs from peer" in report["diverged"][0]["detail"]
    logged = [r.getMessage() for r in caplog.records if r.levelno == logging.ERROR]
    assert len(logged) == 2  # once by each holder
    assert all(f"chunk {chunk.short}: commit 2" in m for m in logged)
    assert check_chain(b.store, chunk) == []  # b's own store is consistent: only comparing tells
    assert forged.id not in {c.id for c in a.log()}


async def test_a_rejoining_holder_compares_at_once(swarm: MakeSwarm) -> None:
    a, b, c = await swarm(3)
    chunk, item = await counter_chunk(a)
    await share(chunk, [b, c])
    assert isinstance(c.store, SqliteStore)
    path, c_id = c.store.path, c.id
    await c.close()
    inject(b, chunk)
    await increment(a, [(TABLE, item)])
    again = Peer(SqliteStore(path), c_id)
    try:
        await again.start("tcp://127.0.0.1:0")
        await again.join(a.address)  # rejoins: fetches the chunk, compares with a and b
        (found,) = again.store.divergences()
        assert found.chunk == chunk
        assert found.peer in (a.id, b.id)  # it fetched one history and sees the other
    finally:
        await again.close()


async def test_a_replica_that_no_longer_matches_its_chain_is_not_sent(
    swarm: MakeSwarm, caplog: pytest.LogCaptureFixture
) -> None:
    a, b = await swarm(2)
    chunk, item = await counter_chunk(a, 5)
    await increment(a, [(TABLE, item)])
    assert isinstance(a.store, SqliteStore)
    con = sqlite3.connect(a.store.path)  # a byte flipped on disk, in a payload that still parses
    con.execute(
        "UPDATE revisions SET data = ? WHERE item_id = ? AND update_time = "
        "(SELECT MIN(update_time) FROM revisions WHERE item_id = ?)",
        (Counter(name="c", value=4).SerializeToString(), item.to_bytes(), item.to_bytes()),
    )
    con.commit()
    con.close()
    with (
        caplog.at_level(logging.ERROR, logger="mapapi.swarm.chain_check"),
        pytest.raises(CorruptRepoError, match="no longer matches its hash chain"),
    ):
        await b.participate(chunk)
    assert any("not sent to another peer" in r.getMessage() for r in caplog.records)
    assert chunk not in {c.id for c in b.chunks()}
