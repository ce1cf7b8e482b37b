"""Idle groups go quiet, over real sockets (DESIGN §13): a peer holding many chunks does
not heartbeat each of them; a proposal wakes a group; followers whose leader's peer died
(as the failure detector says) elect another leader."""

from __future__ import annotations

import time
from collections.abc import Callable

from mapapi.core.ids import ChunkId, PeerId
from mapapi.testing import until
from tests.swarm.raft_world import TICK, Node, World, founded, leader_of, propose_all
from tests.swarm.raft_world import world as world  # the fixture

CHUNKS = [ChunkId.new() for _ in range(10)]


def all_quiet(nodes: list[Node]) -> bool:
    return all(n.groups._groups[c].node.quiet for n in nodes for c in CHUNKS)


async def quiet_groups(world: World, dead: set[PeerId]) -> list[Node]:
    world.alive = lambda peer: peer not in dead
    nodes = await founded(world, CHUNKS)
    for chunk in CHUNKS:
        await propose_all(await leader_of(nodes, chunk), chunk, [b"a"])
    await until(lambda: all_quiet(nodes), timeout=10.0)  # no message marks going quiet
    await until(sent_nothing_for(nodes, 3), timeout=10.0)
    return nodes


def sent_nothing_for(nodes: list[Node], ticks: int) -> Callable[[], bool]:
    """A condition: no node has sent a message for `ticks` ticks. A group marks itself
    quiet when it handles its last heartbeat, and its reply may still be on its way
    out (flushed with the next batch) on a loaded machine."""
    last: list[int] = []
    since = time.monotonic()

    def quiet() -> bool:
        nonlocal last, since
        now = [n.groups.mail.messages_sent for n in nodes]
        if now != last:
            last, since = now, time.monotonic()
        return time.monotonic() - since > ticks * TICK

    return quiet


async def test_idle_groups_send_nothing_until_a_proposal_wakes_one(world: World) -> None:
    nodes = await quiet_groups(world, set())
    sent = [n.groups.mail.messages_sent for n in nodes]
    # An absence has no event to await: watch for 20 ticks, in which every group
    # would have heartbeated 20 times.
    since = time.monotonic()
    await until(lambda: time.monotonic() > since + 20 * TICK)
    leader = await leader_of(nodes, CHUNKS[0])
    assert [n.groups.mail.messages_sent for n in nodes] == sent
    await propose_all(leader, CHUNKS[0], [b"b"])  # wakes it; the others stay quiet
    for node in nodes:
        await node.wait(lambda n=node: n.applied[CHUNKS[0]] == [b"a", b"b"])
    assert all(n.groups._groups[c].node.quiet for n in nodes for c in CHUNKS[1:])


async def test_followers_whose_leader_died_elect_another(world: World) -> None:
    dead: set[PeerId] = set()
    nodes = await quiet_groups(world, dead)
    leader = await leader_of(nodes, CHUNKS[0])
    await leader.stop()
    world.nodes.remove(leader)
    dead.add(leader.id)  # the failure detector says so
    rest = [n for n in nodes if n is not leader]
    successor = await leader_of(rest, CHUNKS[0])
    await propose_all(successor, CHUNKS[0], [b"after"])
    for node in rest:
        await node.wait(lambda n=node: n.applied[CHUNKS[0]][-1:] == [b"after"])
