"""Views in a swarm (DESIGN §13): a view begun now sees every commit acknowledged
before its first read, on any peer, even one its replica has not applied yet and
one stamped past the reader's Lamport clock; a view that has read stays at its
time, and a view begun at a given time never moves.

The writer's links are slowed down, so its commits reach the other holder well
after they were acknowledged (a group of a voter and a learner commits on the
voter alone), and nothing the writer sends moves the reader's clock meanwhile.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable

import pytest

from mapapi import ChunkId, ConflictError, ItemId, Peer
from mapapi.net.shaping import LinkShape, Shaper
from tests.swarm.conftest import TABLE, Counter, counter_chunk, net, share, value

LAG = 0.15
"""Seconds every message of the writer takes to arrive."""


async def writer_and_reader(make_peer: Callable[..., Awaitable[Peer]]) -> tuple[Peer, Peer]:
    """A writer whose messages arrive LAG late and a reader, joined."""
    writer, reader = await make_peer(), await make_peer()
    await writer.start(shaper=Shaper(LinkShape(latency=LAG)))
    await reader.start()
    await reader.join(writer.address)
    return writer, reader


async def shared_counter(
    make_peer: Callable[..., Awaitable[Peer]],
) -> tuple[Peer, Peer, ChunkId, ItemId]:
    """A writer holding a counter at 0 (its chunk's voter) and a reader holding it
    too (a learner)."""
    writer, reader = await writer_and_reader(make_peer)
    chunk, item = await counter_chunk(writer, 0)
    await share(chunk, [reader])
    return writer, reader, chunk, item


async def set_counter(peer: Peer, item: object, to: int) -> int:
    """Commit the counter `item` at `to` on `peer`, blind; the commit's time."""
    tx = peer.begin()
    tx.update(TABLE, item, Counter(name="c", value=to))  # type: ignore[arg-type]
    record = await tx.commit(f"set {to}")
    assert record is not None
    return record.time


async def test_a_view_begun_after_a_commit_elsewhere_reads_it(
    make_peer: Callable[..., Awaitable[Peer]],
) -> None:
    writer, reader, _, item = await shared_counter(make_peer)
    for to in (1, 2, 3):
        committed = await set_counter(writer, item, to)
        # acknowledged before the reader applied it (or heard of its time)
        tx = reader.begin()
        read = await tx.get(TABLE, item)
        assert read is not None
        assert read.value == to
        assert tx.begin_time >= committed  # as if the view had begun after it


async def test_a_view_that_has_read_stays_at_its_time(
    make_peer: Callable[..., Awaitable[Peer]],
) -> None:
    writer, reader = await writer_and_reader(make_peer)
    chunk, first = await counter_chunk(writer, 0)
    tx = writer.begin()
    second = tx.insert(TABLE, Counter(name="d", value=0), chunk)
    await tx.commit("second")
    await share(chunk, [reader])

    view = reader.begin()
    assert (await view.get(TABLE, first)).value == 0  # type: ignore[union-attr]
    begun = view.begin_time
    tx = writer.begin()
    tx.update(TABLE, first, Counter(name="c", value=1))
    tx.update(TABLE, second, Counter(name="d", value=1))
    await tx.commit("both")
    assert await value(reader, second) == 1  # a new view sees it
    assert (await view.get(TABLE, second)).value == 0  # type: ignore[union-attr]
    assert (await view.items(TABLE))[first].value == 0  # type: ignore[attr-defined]
    assert view.begin_time == begun
    view.update(TABLE, first, Counter(name="c", value=9))
    with pytest.raises(ConflictError):
        await view.commit("from the old view")


async def test_a_view_that_wrote_first_keeps_its_time(
    make_peer: Callable[..., Awaitable[Peer]],
) -> None:
    writer, reader, chunk, item = await shared_counter(make_peer)
    view = reader.begin()
    begun = view.begin_time
    view.insert(TABLE, Counter(name="e", value=0), chunk)
    await set_counter(writer, item, 1)
    await view.items(TABLE)
    assert view.begin_time == begun


async def test_a_view_at_a_given_time_never_moves(
    make_peer: Callable[..., Awaitable[Peer]],
) -> None:
    writer, reader, _, item = await shared_counter(make_peer)
    assert await value(reader, item) == 0
    then = reader.now()
    await set_counter(writer, item, 1)
    assert await value(reader, item) == 1
    assert await value(reader, item, at=then) == 0


async def test_a_view_of_an_up_to_date_chunk_adds_nothing_to_its_log(
    make_peer: Callable[..., Awaitable[Peer]],
) -> None:
    writer, reader, chunk, item = await shared_counter(make_peer)
    committed = await set_counter(writer, item, 1)
    assert await value(reader, item) == 1
    before = net(writer).groups.applied(chunk)
    assert reader.clock.now() > committed  # messages moved the Lamport clock past it
    tx = reader.begin()
    assert (await tx.get(TABLE, item)).value == 1  # type: ignore[union-attr]
    assert net(writer).groups.applied(chunk) == before  # no time floor was needed


async def test_a_view_reads_its_own_write_in_a_chunk_it_reads_second(
    make_peer: Callable[..., Awaitable[Peer]],
) -> None:
    writer, _ = await writer_and_reader(make_peer)
    _, older = await counter_chunk(writer, 0, name="older")
    _, newer = await counter_chunk(writer, 0, name="newer")
    committed = await set_counter(writer, newer, 5)
    view = writer.begin()
    assert (await view.get(TABLE, older)).value == 0  # type: ignore[union-attr]
    assert view.begin_time >= committed  # the older chunk's clock did not pull it back
    assert (await view.get(TABLE, newer)).value == 5  # type: ignore[union-attr]
