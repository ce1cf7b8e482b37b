"""Lookup by reference (the Chord index of holders) and by peer (DESIGN §7, issue 4 §2).

Every started peer is a node of the Chord ring on its swarm endpoint. These
peers run the ring's repair tasks with short periods; each test first waits,
round by round, until the ring agrees with the `SortedRing` oracle, so that
every registration lands at the key's real owner.
"""

from __future__ import annotations

from mapapi import ChunkId, Peer
from mapapi.lookup.dht.ring import chunk_key
from mapapi.service.ops import RepoOperations
from mapapi.service.transfer_ops import SwarmOperations
from mapapi.swarm.replication import decode_holder

from .conftest import TABLE, MakePeer, counter_chunk, lookup_swarm, net, value


async def indexed_holders(asker: Peer, chunk: ChunkId) -> set[str]:
    """The ids of the holders the Chord index lists for `chunk`, asked by `asker`."""
    raw = await net(asker).chord.get(chunk_key(chunk))
    return {str(decode_holder(entry).id) for entry in raw}


def holders_queries(peer: Peer) -> int:
    """HoldersQuery messages `peer` sent (the fallback: asking every member)."""
    sent = net(peer).rpc.transport.stats.sent_by_type().get("holders_query")
    return 0 if sent is None else sent.messages


async def test_holders_are_registered_on_create_and_participate_and_removed_on_leave(
    make_peer: MakePeer,
) -> None:
    a, b, c = await lookup_swarm(make_peer, 3)
    chunk, _ = await counter_chunk(a)
    for asker in (a, b, c):
        assert await indexed_holders(asker, chunk) == {str(a.id)}

    await b.participate(chunk)
    assert await indexed_holders(c, chunk) == {str(a.id), str(b.id)}
    assert holders_queries(b) == 0  # found through the index

    await b.leave_chunk(chunk)
    assert await indexed_holders(c, chunk) == {str(a.id)}

    await a.close()  # a graceful stop withdraws a from the index too
    assert await indexed_holders(c, chunk) == set()


async def test_a_peer_finds_holders_through_the_index_and_participates_by_id(
    make_peer: MakePeer,
) -> None:
    peers = await lookup_swarm(make_peer, 6)
    holder, sharer, reader = peers[0], peers[1], peers[5]
    chunk, item = await counter_chunk(holder, 41)
    await sharer.participate(chunk)

    found = await net(reader).replicator.find_holders(chunk=chunk)
    assert {str(m.id) for m in found.holders} == {str(holder.id), str(sharer.id)}

    # `mapctl chunk participate ID` on any peer: the full id alone is enough
    joined = await SwarmOperations(reader).participate(str(chunk))
    assert joined["table"] == TABLE
    assert set(joined["holders"]) == {holder.id, sharer.id, reader.id}
    assert await value(reader, item) == 41
    assert holders_queries(reader) == 0  # the index answered: no member was asked
    assert await indexed_holders(peers[3], chunk) == {
        str(holder.id),
        str(sharer.id),
        str(reader.id),
    }


async def test_without_an_index_entry_the_members_are_asked(make_peer: MakePeer) -> None:
    a, b = await lookup_swarm(make_peer, 2)
    chunk, item = await counter_chunk(a, 7)
    await net(a).replicator.unregister(chunk)  # say the entry was lost
    assert await indexed_holders(b, chunk) == set()

    assert await b.participate(chunk) == TABLE
    assert holders_queries(b) > 0
    assert await value(b, item) == 7
    assert await indexed_holders(a, chunk) == {str(b.id)}  # b registered itself


async def test_rejoin_registers_again(make_peer: MakePeer) -> None:
    a, b, c = await lookup_swarm(make_peer, 3)
    chunk, _ = await counter_chunk(a)
    await b.participate(chunk)
    await net(b).replicator.withdraw_all()  # as a graceful stop does
    assert await indexed_holders(c, chunk) == {str(a.id)}

    assert await b.rejoin() == [chunk]
    assert await indexed_holders(c, chunk) == {str(a.id), str(b.id)}


async def test_chunk_list_by_peer(make_peer: MakePeer) -> None:
    a, b = await lookup_swarm(make_peer, 2)
    first, _ = await counter_chunk(a)
    second = await a.create_chunk(TABLE)

    listed = await b.peer_chunks(a.address)
    assert sorted((c.chunk, c.table, c.items) for c in listed) == sorted(
        [(first, TABLE, 1), (second, TABLE, 0)]
    )
    assert await b.peer_chunks(b.address) == []

    # a peer that is not on the network asks over a connection of its own
    offline = await make_peer()
    rows = (await RepoOperations(offline).chunk_list(table=TABLE, peer=a.address))["chunks"]
    assert sorted(r["id"] for r in rows) == sorted([first, second])
