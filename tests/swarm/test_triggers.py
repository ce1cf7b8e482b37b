"""Local triggers (DESIGN §8, issue 6 §1): callbacks once per applied commit,
local commits included, in commit order, off the receive loop; a failing
callback never breaks the peer. Includes the C++ original's ping-pong test."""

from __future__ import annotations

import asyncio
import threading

from mapapi import ConflictError, ItemId, NetworkError, Peer
from mapapi.swarm.triggers import CommitEvent

from .conftest import TABLE, Counter, MakeSwarm, counter_chunk, log_ids, net, share, value

LIMIT = 10


async def quiet(*peers: Peer) -> None:
    """Wait until no peer has a commit waiting for, or inside, a trigger."""
    while True:
        for peer in peers:
            await peer.triggers.drained()
        if all(peer.triggers.idle for peer in peers):
            return


async def settled(*peers: Peer) -> None:
    """Wait until every peer applied every commit of its chunks' logs and ran the
    triggers they fired (a commit returns once a majority of the chunk's voters
    took it: a learner applies it, and fires its triggers, a moment later)."""
    while True:
        await quiet(*peers)
        before = [net(p).groups.applied(c.id) for p in peers for c in p.chunks()]
        for peer in peers:
            await log_ids(peer)  # caught up with the chunks' leaders
        await quiet(*peers)
        if [net(p).groups.applied(c.id) for p in peers for c in p.chunks()] == before:
            return


def bump_below_limit(peer: Peer, item: ItemId, fired: list[int]) -> object:
    """A trigger that increments the counter while it is below LIMIT (the
    original's ping-pong callback), retrying when another peer got there first."""

    async def trigger(event: CommitEvent) -> None:
        fired.append(event.record.time)
        while True:
            tx = peer.begin()
            current = await tx.get(TABLE, item)
            assert current is not None
            if current.value >= LIMIT:
                return
            tx.update(TABLE, item, Counter(name=current.name, value=current.value + 1))
            try:
                await tx.commit(f"{peer.name}: {current.value + 1}")
                return
            except (ConflictError, NetworkError):
                continue

    return trigger


async def test_ping_pong_ends_at_exactly_ten(swarm: MakeSwarm) -> None:
    a, b = await swarm(2)
    chunk, item = await counter_chunk(a, 0)
    await share(chunk, [b])
    fired: dict[str, list[int]] = {"a": [], "b": []}
    a.on_commit(bump_below_limit(a, item, fired["a"]), chunk=chunk)  # type: ignore[arg-type]
    b.on_commit(bump_below_limit(b, item, fired["b"]), chunk=chunk)  # type: ignore[arg-type]

    tx = a.begin()
    tx.update(TABLE, item, Counter(name="c", value=0))
    await tx.commit("serve")
    await settled(a, b)

    assert await value(a, item) == LIMIT
    assert await value(b, item) == LIMIT
    history = [r for r in a.history(item) if not r.removed]
    assert [Counter.FromString(r.data).value for r in history] == [0, 0, *range(1, LIMIT + 1)]
    assert await log_ids(a) == await log_ids(b)
    # every commit from the serve on fired both peers' triggers, local ones included
    commits = sorted(r.update_time for r in history[1:])
    assert fired["a"] == commits
    assert fired["b"] == commits


async def test_a_trigger_sees_each_commit_once_in_order_with_its_changes(
    swarm: MakeSwarm,
) -> None:
    a, b = await swarm(2)
    chunk, first = await counter_chunk(a, 1)
    await share(chunk, [b])
    seen: list[CommitEvent] = []
    b.on_commit(seen.append, table=TABLE)  # a plain function runs in a worker thread

    tx = a.begin()
    second = tx.insert(TABLE, Counter(name="d", value=2), chunk)
    tx.update(TABLE, first, Counter(name="c", value=5))
    await tx.commit("insert and update")
    tx = b.begin()
    assert await tx.get(TABLE, second) is not None  # b's replica caught up with a's commit
    tx.remove(TABLE, second)
    await tx.commit("b removes d")
    await settled(a, b)

    assert [e.record.message for e in seen] == ["insert and update", "b removes d"]
    assert (seen[0].inserted, seen[0].updated, seen[0].removed) == ((second,), (first,), ())
    assert (seen[1].inserted, seen[1].updated, seen[1].removed) == ((), (), (second,))


async def test_triggers_watch_their_chunk_or_table_only(swarm: MakeSwarm) -> None:
    (a,) = await swarm(1)
    watched, item = await counter_chunk(a, 0)
    other, other_item = await counter_chunk(a, 0, name="other")
    on_chunk: list[str] = []
    on_table: list[str] = []
    a.on_commit(lambda e: on_chunk.append(e.record.message), chunk=watched)
    a.on_commit(lambda e: on_table.append(e.record.message), table=TABLE)
    for target, name in ((item, "watched"), (other_item, "other")):
        tx = a.begin()
        tx.update(TABLE, target, Counter(name=name, value=1))
        await tx.commit(name)
    await quiet(a)
    assert on_chunk == ["watched"]
    assert on_table == ["watched", "other"]
    assert other != watched


async def test_a_failing_trigger_is_logged_and_the_peer_goes_on(
    swarm: MakeSwarm, caplog: object
) -> None:
    a, b = await swarm(2)
    chunk, item = await counter_chunk(a, 0)
    await share(chunk, [b])
    after: list[str] = []

    def broken(event: CommitEvent) -> None:
        raise RuntimeError("callback bug")

    b.on_commit(broken, chunk=chunk)
    b.on_commit(lambda e: after.append(e.record.message), chunk=chunk)
    for n in (1, 2):
        tx = a.begin()
        tx.update(TABLE, item, Counter(name="c", value=n))
        await tx.commit(f"set {n}")
    await settled(a, b)

    assert after == ["set 1", "set 2"]
    assert await value(b, item) == 2
    assert "callback bug" in caplog.text  # type: ignore[attr-defined]


async def test_callbacks_run_off_the_receive_loop(swarm: MakeSwarm) -> None:
    a, b = await swarm(2)
    chunk, item = await counter_chunk(a, 0)
    await share(chunk, [b])
    release = threading.Event()
    entered = asyncio.Event()
    loop = asyncio.get_running_loop()

    def slow(event: CommitEvent) -> None:
        loop.call_soon_threadsafe(entered.set)
        release.wait(timeout=30)

    b.on_commit(slow, chunk=chunk)
    tx = a.begin()
    tx.update(TABLE, item, Counter(name="c", value=1))
    await tx.commit("one")
    await entered.wait()
    # while b's callback blocks, b still takes part in commits
    tx = a.begin()
    tx.update(TABLE, item, Counter(name="c", value=2))
    await tx.commit("two")
    assert await value(b, item) == 2
    release.set()
    await quiet(a, b)
    assert b.remove_trigger(1) is True
