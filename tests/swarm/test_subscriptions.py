"""Remote subscriptions (DESIGN §8, issue 6 §2 and §4): a subscriber hears about
every commit inside its region and nothing outside, filters drop what does not
match, pushes come in commit order, and subscriptions survive peers joining
and leaving; a cancelled or vanished subscriber gets nothing more.

Each test waits until the Chord ring agrees with the oracle (`lookup_swarm`),
so subscriptions land at their cells' real owners. A push is acknowledged
before the commit that caused it returns, so after a commit the subscriber's
queue already holds what it will ever get for it.
"""

from __future__ import annotations

from google.protobuf import struct_pb2

from mapapi import ChunkId, ItemId, Peer
from mapapi.lookup.spatial import BBox
from mapapi.swarm.node import ChordOptions
from mapapi.swarm.subscriptions import Subscription, SubscriptionSpec
from mapapi.swarm.triggers import CommitEvent

from .conftest import FAST, MakePeer, lookup_swarm, net

ROOMS = "rooms"
REGION = BBox(0, 0, 0, 10, 10, 3)


def thing(x: float, y: float, **fields: object) -> struct_pb2.Struct:
    item = struct_pb2.Struct()
    item.update({"bbox": [x, y, 0, x + 1, y + 1, 1], **fields})
    return item


async def rooms(peer: Peer) -> ChunkId:
    await peer.create_table(ROOMS, "google.protobuf.Struct")
    return await peer.create_chunk(ROOMS)


async def put(peer: Peer, chunk: ChunkId, item: struct_pb2.Struct, message: str) -> ItemId:
    tx = peer.begin()
    item_id = tx.insert(ROOMS, item, chunk)
    await tx.commit(message)
    return item_id


def received(subscription: Subscription) -> list[CommitEvent]:
    """Every event queued so far."""
    events = []
    while not subscription.events.empty():
        events.append(subscription.events.get_nowait())
    return events


async def test_every_commit_inside_the_region_and_nothing_outside(make_peer: MakePeer) -> None:
    a, b, c = await lookup_swarm(make_peer, 3)
    chunk = await rooms(a)
    subscription = await c.subscribe(SubscriptionSpec(REGION))

    inside = await put(a, chunk, thing(1, 1), "inside")
    await put(a, chunk, thing(50, 50), "outside")
    edge = await put(a, chunk, thing(10, 10), "touching the region's corner")
    tx = a.begin()
    tx.update(ROOMS, inside, thing(60, 60))  # leaves the region: news
    await tx.commit("moves out")
    tx = a.begin()
    tx.update(ROOMS, inside, thing(70, 70))  # outside before and after
    await tx.commit("moves further out")
    tx = a.begin()
    tx.remove(ROOMS, edge)
    await tx.commit("removes the corner one")

    events = received(subscription)
    assert [e.record.message for e in events] == [
        "inside",
        "touching the region's corner",
        "moves out",
        "removes the corner one",
    ]
    assert [(e.inserted, e.updated, e.removed) for e in events] == [
        ((inside,), (), ()),
        ((edge,), (), ()),
        ((), (inside,), ()),
        ((), (), (edge,)),
    ]
    # only the matching revisions travel: the commit's other items stay home
    tx = a.begin()
    near = tx.insert(ROOMS, thing(2, 2), chunk)
    tx.insert(ROOMS, thing(90, 90), chunk)
    await tx.commit("one in, one out")
    (event,) = received(subscription)
    assert [r.item_id for r in event.revisions] == [near]
    assert b.id != c.id


async def test_table_and_field_filters_drop_what_does_not_match(make_peer: MakePeer) -> None:
    a, b = await lookup_swarm(make_peer, 2)
    chunk = await rooms(a)
    await a.create_table("notes", "google.protobuf.Struct")
    notes = await a.create_chunk("notes")
    doors = await b.subscribe(SubscriptionSpec(REGION, ROOMS, (("kind", "door"), ("floor", 1))))

    door = await put(a, chunk, thing(1, 1, kind="door", floor=1), "a door")
    await put(a, chunk, thing(2, 2, kind="window", floor=1), "a window")
    await put(a, chunk, thing(3, 3, kind="door", floor=2), "a door upstairs")
    tx = a.begin()
    tx.insert("notes", thing(1, 1, kind="door", floor=1), notes)
    await tx.commit("a note about a door")

    assert [(e.record.message, e.inserted) for e in received(doors)] == [("a door", (door,))]


async def test_pushes_come_in_commit_order_from_several_writers(make_peer: MakePeer) -> None:
    a, b, c = await lookup_swarm(make_peer, 3)
    chunk = await rooms(a)
    await b.participate(chunk)
    subscription = await c.subscribe(SubscriptionSpec(REGION))

    for n in range(6):
        writer = (a, b)[n % 2]
        await put(writer, chunk, thing(n, n), f"{writer.name} {n}")

    events = received(subscription)
    assert [e.record.message for e in events] == [f"{(a, b)[n % 2].name} {n}" for n in range(6)]
    times = [e.record.time for e in events]
    assert times == sorted(times)


async def test_subscriptions_survive_peers_joining_and_leaving(make_peer: MakePeer) -> None:
    peers = await lookup_swarm(make_peer, 4)
    a, subscriber = peers[0], peers[1]
    chunk = await rooms(a)
    subscription = await subscriber.subscribe(SubscriptionSpec(REGION))
    for leaver in peers[2:]:
        await leaver.close()
    newcomers = [await make_peer() for _ in range(3)]
    for peer in newcomers:
        await peer.start("tcp://127.0.0.1:0", chord=FAST)
        await peer.join(a.address)
    everyone = [a, subscriber, *newcomers]
    await settled(everyone)  # keys were handed over on each join and leave

    for n, writer in enumerate(everyone):
        if writer is not a:
            await writer.participate(chunk)
        await put(writer, chunk, thing(n, n), f"after the churn {n}")
    assert [e.record.message for e in received(subscription)] == [
        f"after the churn {n}" for n in range(len(everyone))
    ]


async def settled(peers: list[Peer]) -> None:
    from .conftest import MAX_ROUNDS, _ring_correct

    for _ in range(MAX_ROUNDS):
        if _ring_correct(peers):
            return
        await net(peers[0]).chord.next_round()
    raise AssertionError("the ring did not settle")


async def test_a_cancelled_subscription_gets_nothing_more(make_peer: MakePeer) -> None:
    a, b = await lookup_swarm(make_peer, 2)
    chunk = await rooms(a)
    subscription = await b.subscribe(SubscriptionSpec(REGION))
    await put(a, chunk, thing(1, 1), "before")
    assert await b.unsubscribe(subscription) is True
    assert await b.unsubscribe(subscription) is False
    pushes = net(a).subscriptions.pushes
    await put(a, chunk, thing(2, 2), "after")
    assert [e.record.message for e in received(subscription)] == ["before"]
    assert net(a).subscriptions.pushes == pushes


SHORT = ChordOptions(
    stabilize=0.02, fix_fingers=0.1, check_predecessor=0.05, timeout=0.3, holder_ttl=0.6
)


async def test_a_vanished_subscriber_is_dropped_when_its_ttl_expires(
    make_peer: MakePeer,
) -> None:
    a, b = [await make_peer() for _ in range(2)]
    for peer in (a, b):
        await peer.start("tcp://127.0.0.1:0", chord=SHORT)
    await b.join(a.address)
    await settled([a, b])
    chunk = await rooms(a)
    await b.subscribe(SubscriptionSpec(REGION))
    index = net(a).subscriptions.index
    assert index is not None
    assert await index.members(REGION) != []

    # b crashes: no goodbye, no withdrawal, its endpoint just goes away
    await net(b).subscriptions.close()
    await net(b).rpc.close()
    while await index.members(REGION):  # each round of a's ring is a tick of time
        await net(a).chord.next_round()
    pushes = net(a).subscriptions.pushes
    await put(a, chunk, thing(1, 1), "nobody listens")
    assert net(a).subscriptions.pushes == pushes


async def test_a_view_begun_after_a_push_includes_its_commit(make_peer: MakePeer) -> None:
    """The subscriber holds no replica of the chunk: only the push told it of the
    commit, and a view it begins afterwards must be at or past that commit."""
    a, b = await lookup_swarm(make_peer, 2)
    chunk = await rooms(a)
    subscription = await b.subscribe(SubscriptionSpec(REGION))
    for n in range(3):  # a's clock runs ahead of b's
        await put(a, chunk, thing(50, 50), f"outside {n}")
    await put(a, chunk, thing(1, 1), "inside")
    (event,) = received(subscription)
    assert chunk not in b.store.chunk_ids()
    assert b.begin().begin_time >= event.record.time
