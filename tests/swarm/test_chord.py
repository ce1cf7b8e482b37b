"""The Chord ring and its soft-state values (DESIGN §7, issue 4 §1 and §5).

Every node runs on its own real `Rpc` over `ZmqTransport` on 127.0.0.1, all in
this process. The background tasks run with long periods; tests drive the
ring with explicit `stabilize_once` / `fix_fingers_once` rounds, bounded by a
round count, and compare it with the `SortedRing` oracle.
"""

from __future__ import annotations

import asyncio
import gc
import math
import random
import warnings
from collections.abc import AsyncIterator, Awaitable, Callable
from typing import Any

import pytest

from mapapi.core.ids import ChunkId, PeerId
from mapapi.lookup.dht.chord import ChordNode, key_bytes
from mapapi.lookup.dht.ring import SortedRing, chunk_key
from mapapi.net.messages import Ack, ChordAdd, ChordRemove
from mapapi.net.rpc import Rpc
from mapapi.net.transport import ZmqTransport

K = 4  # successor list length
TIMEOUT = 2.0  # per request: only dead nodes reach it, live ones answer sooner even under load

MakeRing = Callable[..., Awaitable[list[ChordNode]]]


@pytest.fixture
async def make_node() -> AsyncIterator[Callable[..., Awaitable[ChordNode]]]:
    """Factory of started Chord nodes, each on its own Rpc; all closed at teardown."""
    made: list[ChordNode] = []

    async def _make(**options: Any) -> ChordNode:
        peer_id = PeerId.new()
        rpc = Rpc(ZmqTransport(peer_id))
        await rpc.start("tcp://127.0.0.1:0")
        periods = {"stabilize_period": 30.0, "fix_fingers_period": 30.0}
        node = ChordNode(rpc, peer_id, **{"timeout": TIMEOUT, **periods, **options})
        node.start()
        made.append(node)
        return node

    yield _make
    for node in made:
        await node.close()
    await asyncio.gather(*(node.rpc.close() for node in made))


@pytest.fixture
def make_ring(make_node: Callable[..., Awaitable[ChordNode]]) -> MakeRing:
    """Factory: n nodes, each joined through a random earlier one, then stabilized."""

    async def _ring(n: int, **options: Any) -> list[ChordNode]:
        nodes = [await make_node(**options)]
        await grow(nodes, n - 1, make_node, **options)
        return nodes

    return _ring


# -- helpers -------------------------------------------------------------------------


async def grow(
    nodes: list[ChordNode], n: int, make_node: Callable[..., Awaitable[ChordNode]], **options: Any
) -> None:
    """Join `n` new nodes to the ring of `nodes`, then stabilize it and fix fingers."""
    rng = random.Random(len(nodes))
    for _ in range(n):
        node = await make_node(**options)
        await node.join(rng.choice(nodes).me.address)
        nodes.append(node)
    await converge(nodes)


def ring_ok(nodes: list[ChordNode]) -> bool:
    """Whether every successor list and predecessor matches the oracle."""
    oracle = SortedRing(n.key for n in nodes)
    return all(
        [s.key for s in n.successors] == oracle.successor_list(n.key, K)
        and (n.predecessor or n.me).key == oracle.predecessor(n.key)
        for n in nodes
    )


async def converge(nodes: list[ChordNode], max_rounds: int | None = None) -> int:
    """Stabilize rounds on every node until the ring matches the oracle, then fix
    every finger table; returns the rounds it took."""
    limit = max_rounds or 2 * len(nodes) + 10
    for rounds in range(limit):  # noqa: B007
        if ring_ok(nodes):
            break
        await asyncio.gather(*(n.stabilize_once() for n in nodes), return_exceptions=True)
        await asyncio.gather(*(n.check_predecessor_once() for n in nodes), return_exceptions=True)
    assert ring_ok(nodes), f"ring not stable after {limit} rounds"
    await asyncio.gather(*(n.fix_fingers_once() for n in nodes))
    return rounds


def walk(nodes: list[ChordNode]) -> list[int]:
    """The node keys met following successor pointers from the first node, once round."""
    by_key = {n.key: n for n in nodes}
    seen = [nodes[0].key]
    while (following := by_key[seen[-1]].successors[0].key) != seen[0]:
        assert following not in seen, "successor pointers loop before closing the ring"
        seen.append(following)
    return seen


def keys(count: int, seed: int) -> list[int]:
    """Ring keys of random chunk ids."""
    rng = random.Random(seed)
    return [chunk_key(ChunkId(f"{rng.getrandbits(128):032x}")) for _ in range(count)]


async def assert_lookups_agree(nodes: list[ChordNode], probes: list[int]) -> list[int]:
    """Every node looks up every probe and every node key; returns the hop counts."""
    oracle = SortedRing(n.key for n in nodes)
    wanted = [*probes, *oracle.nodes, *(k + 1 for k in oracle.nodes[:-1])]
    hops: list[int] = []
    for node in nodes:
        found = await asyncio.gather(*(node.find_successor(k) for k in wanted))
        for key, (owner, address, count) in zip(wanted, found, strict=True):
            assert owner == oracle.successor(key), (
                f"{node.key:#x} misroutes {key:#x} to {owner:#x}; it suspects "
                f"{sorted(map(hex, node._suspected()))}; ring {list(map(hex, oracle.nodes))}"
            )
            assert address == next(n.me.address for n in nodes if n.key == owner)
            hops.append(count)
    return hops


# -- the ring --------------------------------------------------------------------------


class TestRing:
    @pytest.mark.parametrize("n", [16, 32, 64])
    async def test_lookups_from_every_node_agree_with_the_oracle(
        self, make_ring: MakeRing, n: int, record_property: Callable[[str, object], None]
    ) -> None:
        nodes = await make_ring(n)
        oracle = SortedRing(node.key for node in nodes)
        assert walk(nodes) == [*oracle.nodes[oracle.nodes.index(nodes[0].key) :], *oracle.nodes][:n]
        for node in nodes:
            assert node.fingers == [
                next(m.me for m in nodes if m.key == f) for f in oracle.finger_table(node.key)
            ]
        hops = await assert_lookups_agree(nodes, keys(20, n))
        mean = sum(hops) / len(hops)
        record_property("mean_hops", mean)
        print(f"\nN={n}: mean hops {mean:.2f}, max {max(hops)}, target {math.log2(n) / 2 + 1:.2f}")
        assert mean <= math.log2(n) + 1
        assert max(hops) <= 2 * math.log2(n) + 2

    async def test_a_lone_node_is_its_own_successor(self, make_ring: MakeRing) -> None:
        (node,) = await make_ring(1)
        assert await node.find_successor(12345) == (node.key, node.me.address, 0)
        await node.add(7, b"m", ttl=60)
        assert await node.get(7) == {b"m"}

    async def test_the_periodic_tasks_build_the_ring_by_themselves(
        self, make_node: Callable[..., Awaitable[ChordNode]]
    ) -> None:
        fast = {
            "stabilize_period": 0.02,
            "fix_fingers_period": 0.05,
            "check_predecessor_period": 0.05,
        }
        nodes = [await make_node(**fast)]
        for _ in range(7):
            node = await make_node(**fast)
            await node.join(nodes[0].me.address)
            nodes.append(node)
        oracle = SortedRing(n.key for n in nodes)
        async with asyncio.timeout(10):
            # the tasks under test are the only thing that changes the ring here
            while not (
                ring_ok(nodes)
                and all(
                    n.fingers
                    == [next(m.me for m in nodes if m.key == f) for f in oracle.finger_table(n.key)]
                    for n in nodes
                )
            ):
                await nodes[0].next_round()
        await assert_lookups_agree(nodes, keys(10, 1))

    async def test_two_rings_a_partition_left_merge_into_one(self, make_ring: MakeRing) -> None:
        """Issue 7 §4: the halves of a healed partition each repaired into a ring of
        their own; every node merging now and then through a random member (as a
        peer's swarm does) makes them one ring again: lookups agree, data is found."""
        left, right = await make_ring(6), await make_ring(6)
        nodes = left + right
        rng = random.Random(12)
        for _ in range(len(nodes)):
            if ring_ok(nodes):
                break
            await asyncio.gather(
                *(n.merge_through(rng.choice(nodes).me.address) for n in nodes),
                return_exceptions=True,
            )
            for _ in range(3):
                await asyncio.gather(*(n.stabilize_once() for n in nodes))
                await asyncio.gather(*(n.check_predecessor_once() for n in nodes))
        await converge(nodes)
        await assert_lookups_agree(nodes, keys(10, 11))
        # entries refreshed by their owners (as every announcement is) are one set again
        await left[0].add(77, b"from the left", ttl=600)
        await right[0].add(77, b"from the right", ttl=600)
        for node in nodes:
            assert await node.get(77) == {b"from the left", b"from the right"}

    async def test_a_dead_successor_is_skipped(self, make_ring: MakeRing) -> None:
        nodes = await make_ring(8)
        await nodes[0].add(99, b"kept", ttl=60)
        owner = next(n for n in nodes if n.key == SortedRing(m.key for m in nodes).successor(99))
        nodes.remove(owner)
        await owner.close()
        await owner.rpc.close()  # no goodbye: it just dies
        await converge(nodes)
        await assert_lookups_agree(nodes, keys(10, 2))
        for node in nodes:
            assert await node.get(99) == {b"kept"}


# -- values ------------------------------------------------------------------------------


class TestValues:
    async def test_data_survives_joins_and_graceful_leaves_of_half_the_nodes(
        self, make_ring: MakeRing, make_node: Callable[..., Awaitable[ChordNode]]
    ) -> None:
        nodes = await make_ring(16)
        data = {key: {f"m{key % 97}-{j}".encode() for j in range(2)} for key in keys(40, 3)}
        for i, (key, members) in enumerate(data.items()):
            for member in members:
                await nodes[i % len(nodes)].add(key, member, ttl=600)
        await grow(nodes, 16, make_node)
        await self._check(nodes, data)
        rng = random.Random(4)
        for leaver in rng.sample(nodes, len(nodes) // 2):
            nodes.remove(leaver)
            await leaver.leave()
            await leaver.rpc.close()
        await converge(nodes)
        await assert_lookups_agree(nodes, keys(5, 5))
        await self._check(nodes, data)

    async def test_keys_survive_crashes_and_are_copied_again(self, make_ring: MakeRing) -> None:
        """Issue 7 §2: nodes die with no goodbye, one after the other and then an
        owner together with its first successor; the ring repairs itself through
        the successor lists and every key is back on its owner and all K
        successors after each repair."""
        nodes = await make_ring(16)
        data = {key: {f"m{key % 89}-{j}".encode() for j in range(2)} for key in keys(40, 7)}
        for i, (key, members) in enumerate(data.items()):
            for member in members:
                await nodes[i % len(nodes)].add(key, member, ttl=600)
        rng = random.Random(8)
        oracle = SortedRing(n.key for n in nodes)
        owner = next(n for n in nodes if n.key == oracle.successor(next(iter(data))))
        after = next(n for n in nodes if n.key == oracle.successor(owner.key + 1))
        for dead in [*rng.sample([n for n in nodes if n not in (owner, after)], 3), None]:
            victims = [dead] if dead is not None else [owner, after]
            for victim in victims:
                nodes.remove(victim)
                await victim.close()
                await victim.rpc.close()  # no goodbye: it just dies
            await converge(nodes)
            await asyncio.gather(*(n.stabilize_once() for n in nodes))  # the last copies
            await assert_lookups_agree(nodes, keys(5, 9))
            await self._check(nodes, data, copies=K + 1)

    async def _check(
        self, nodes: list[ChordNode], data: dict[int, set[bytes]], copies: int = 2
    ) -> None:
        oracle = SortedRing(n.key for n in nodes)
        by_key = {n.key: n for n in nodes}
        for key, members in data.items():
            owner = by_key[oracle.successor(key)]
            assert owner.storage.get(key, owner.clock()) == members
            placed = [by_key[r] for r in oracle.successors(key, K + 1)]  # owner + K successors
            held = sum(r.storage.get(key, r.clock()) == members for r in placed)
            assert held >= copies, f"key {key:x}: {held} copies"
        for node in nodes:
            got = await asyncio.gather(*(node.get(key) for key in data))
            assert got == list(data.values())

    async def test_concurrent_adds_to_one_key_lose_nothing(self, make_ring: MakeRing) -> None:
        nodes = await make_ring(16)
        key = keys(1, 6)[0]
        members = {node.key: [f"{node.key:x}-{j}".encode() for j in range(5)] for node in nodes}
        await asyncio.gather(
            *(node.add(key, m, ttl=600) for node in nodes for m in members[node.key])
        )
        everything = {m for ms in members.values() for m in ms}
        for node in nodes:
            assert await node.get(key) == everything
        await asyncio.gather(*(node.remove(key, members[node.key][0]) for node in nodes))
        left = everything - {ms[0] for ms in members.values()}
        assert await nodes[3].get(key) == left

    async def test_an_update_sent_to_the_old_owner_reaches_the_new_one(
        self, make_ring: MakeRing
    ) -> None:
        """A lookup through routes older than a join ends at the joiner's successor,
        which handed the joiner its keys already: the update must still reach it."""
        nodes = await make_ring(8)
        oracle = SortedRing(n.key for n in nodes)
        by_key = {n.key: n for n in nodes}
        joiner = nodes[5]
        old_owner = by_key[oracle.successor(joiner.key + 1)]
        sender = next(n for n in nodes if n not in (joiner, old_owner))
        key = joiner.key  # the joiner's own key: it owns it
        for body in (ChordAdd(key_bytes(key), b"late", 600), ChordRemove(key_bytes(key), b"late")):
            await sender.rpc.request(old_owner.me.address, body, expect=Ack)
            wanted = {b"late"} if isinstance(body, ChordAdd) else set()
            assert joiner.storage.get(key, joiner.clock()) == wanted
            assert await sender.get(key) == wanted

    async def test_an_update_copied_to_a_predecessor_that_is_also_successor_goes_once(
        self, make_ring: MakeRing
    ) -> None:
        """In a ring of two, a node's predecessor is its successor too: an update of
        the predecessor's key sent here (through routes older than a join) is copied
        to it once, and no copy is built and left unsent ("never awaited")."""
        first, second = await make_ring(2)
        key = second.key  # owned by `second`, the predecessor of `first`
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            await second.rpc.request(first.me.address, ChordAdd(key_bytes(key), b"m", 600))
            gc.collect()
        assert [str(w.message) for w in caught if "never awaited" in str(w.message)] == []
        assert second.storage.get(key, second.clock()) == {b"m"}

    async def test_a_member_not_refreshed_expires(self, make_ring: MakeRing) -> None:
        now = [1000.0]
        nodes = await make_ring(8, clock=lambda: now[0])
        key = keys(1, 7)[0]
        await nodes[1].add(key, b"refreshed", ttl=10)
        await nodes[2].add(key, b"forgotten", ttl=10)
        now[0] += 6
        await nodes[1].add(key, b"refreshed", ttl=10)  # its owner re-adds it
        assert await nodes[5].get(key) == {b"refreshed", b"forgotten"}
        now[0] += 6
        assert await nodes[5].get(key) == {b"refreshed"}
        await asyncio.gather(*(n.check_predecessor_once() for n in nodes))
        assert all(b"forgotten" not in n.storage.get(key, 0.0) for n in nodes)
        now[0] += 6
        assert await nodes[0].get(key) == set()

    async def test_a_non_positive_ttl_is_refused(self, make_ring: MakeRing) -> None:
        (node,) = await make_ring(1)
        with pytest.raises(ValueError, match="time-to-live"):
            await node.add(1, b"m", ttl=0)
