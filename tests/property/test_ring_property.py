"""Chord routing invariants (mapapi.lookup.dht.ring, DESIGN §7): lookups routed with
`next_hop` over correct finger tables and successor lists agree with the
sorted-ring oracle, and take O(log N) hops.

Routing is simulated purely: each visited node decides with its own finger
table and successor list, taken from `SortedRing` (what a stabilized ring holds).
"""

from __future__ import annotations

import math
import random
from itertools import pairwise

from hypothesis import example, given, settings
from hypothesis import strategies as st

from mapapi.core.ids import PeerId
from mapapi.lookup.dht.ring import (
    RING_BITS,
    RING_SIZE,
    SortedRing,
    closest_preceding,
    distance,
    in_interval,
    next_hop,
    peer_key,
    responsible,
)

SUCCESSORS = 4  # DESIGN §7 default

keys = st.integers(0, RING_SIZE - 1)


class Router:
    """Routes lookups over a stabilized ring, building finger tables on demand."""

    def __init__(self, ring: SortedRing) -> None:
        self.ring = ring
        self._fingers: dict[int, list[int]] = {}

    def route(self, start: int, key: int) -> tuple[int, list[int]]:
        """The answer of a lookup for `key` started at `start`, and the nodes it visited."""
        path, node = [start], start
        last = self.ring.predecessor(key)  # the node that knows the answer
        while True:
            fingers = self._fingers.get(node)
            if fingers is None:
                fingers = self._fingers[node] = self.ring.finger_table(node)
            hop = next_hop(node, key, self.ring.successor_list(node, SUCCESSORS), fingers)
            if hop.final:
                return hop.node, path
            # each forward at least halves the distance to the key's predecessor
            # (Chord paper, proof of Theorem 2): so never more than 160 hops
            assert distance(hop.node, last) <= distance(node, last) // 2
            node = hop.node
            path.append(node)
            assert len(path) <= RING_BITS + 1


def hashed_ring(size: int, seed: int) -> SortedRing:
    """`size` peers with random ids, placed by `peer_key` as in a real swarm."""
    rng = random.Random(seed)
    return SortedRing(peer_key(PeerId.from_bytes(rng.randbytes(16))) for _ in range(size))


class TestRouting:
    # Derandomized: the log2(N) + 1 bound holds with high probability, not for every
    # placement (nodes at key - 2**i, i = 0..159, need 40 hops); with SHA-1 positions
    # it fails about once in 200,000 lookups at N = 256, so a fixed sample cannot flake.
    @settings(max_examples=60, deadline=None, derandomize=True)
    @given(
        size=st.integers(1, 256),
        seed=st.integers(0, 2**32 - 1),
        lookups=st.lists(st.tuples(st.integers(0, 255), keys), min_size=1, max_size=12),
    )
    @example(size=2, seed=1, lookups=[(0, 0), (1, RING_SIZE - 1)])
    @example(size=3, seed=2, lookups=[(2, 1 << 159)])
    @example(size=16, seed=3, lookups=[(i, (i * 0x9E3779B97F4A7C15) << 90) for i in range(12)])
    @example(size=64, seed=4, lookups=[(i * 5, (i * 0x9E3779B97F4A7C15) << 90) for i in range(12)])
    @example(
        size=256, seed=5, lookups=[(i * 21, (i * 0x9E3779B97F4A7C15) << 90) for i in range(12)]
    )
    def test_lookups_agree_with_the_oracle_in_logarithmic_hops(
        self, size: int, seed: int, lookups: list[tuple[int, int]]
    ) -> None:
        ring = hashed_ring(size, seed)
        router = Router(ring)
        bound = math.log2(len(ring)) + 1
        nodes = ring.nodes
        for start_pick, key in lookups:
            start = nodes[start_pick % len(nodes)]
            # also look up a key exactly on a node, and the key just past it
            target = nodes[key % len(nodes)]
            for k in (key, target, (target + 1) % RING_SIZE):
                answer, path = router.route(start, k)
                assert answer == ring.successor(k)
                assert len(path) - 1 <= bound, (len(ring), start, k, path)

    @settings(max_examples=100, deadline=None)
    @given(
        nodes=st.lists(keys, min_size=1, max_size=40),
        start_pick=st.integers(0, 39),
        key=keys,
    )
    def test_any_placement_agrees_with_the_oracle(
        self, nodes: list[int], start_pick: int, key: int
    ) -> None:
        # hypothesis picks positions freely (clusters, ends of the key space, ...)
        ring = SortedRing(nodes)
        start = ring.nodes[start_pick % len(ring)]
        answer, _ = Router(ring).route(start, key)
        assert answer == ring.successor(key)

    def test_adversarial_placement_still_routes(self) -> None:
        key = 12345
        ring = SortedRing((key - (1 << i)) % RING_SIZE for i in range(RING_BITS))
        answer, path = Router(ring).route((key - (1 << (RING_BITS - 1))) % RING_SIZE, key)
        assert answer == ring.successor(key)
        # one node per distance halving: each hop jumps to the end of the successor
        # list, far beyond log2(N) + 1 = 8.3 hops, but still correct and bounded
        assert len(path) - 1 == math.ceil((RING_BITS - 1) / SUCCESSORS)


class TestArithmetic:
    @given(x=keys, a=keys, b=keys)
    def test_open_interval_is_half_open_less_its_end(self, x: int, a: int, b: int) -> None:
        assert in_interval(x, a, b, inclusive_right=False) == (
            in_interval(x, a, b, inclusive_right=True) and x != b
        )

    @given(x=keys, a=keys, b=keys)
    def test_two_half_open_arcs_split_the_ring(self, x: int, a: int, b: int) -> None:
        first = in_interval(x, a, b, inclusive_right=True)
        second = in_interval(x, b, a, inclusive_right=True)
        if a == b:
            assert first
            assert second
        else:
            assert first != second

    @given(nodes=st.lists(keys, min_size=1, max_size=30), key=keys)
    def test_exactly_one_node_is_responsible_for_a_key(self, nodes: list[int], key: int) -> None:
        ring = SortedRing(nodes)
        owners = [n for n in ring if responsible(key, n, ring.predecessor(n))]
        assert owners == [ring.successor(key)]

    @given(
        n=keys,
        key=keys,
        fingers=st.lists(st.one_of(st.none(), keys), max_size=20),
        successors=st.lists(keys, max_size=4),
    )
    def test_closest_preceding_equals_brute_force(
        self, n: int, key: int, fingers: list[int | None], successors: list[int]
    ) -> None:
        known = {c for c in (*fingers, *successors) if c is not None}
        before = [c for c in known if in_interval(c, n, key, inclusive_right=False)]
        expected = max(before, key=lambda c: distance(n, c), default=n)
        assert closest_preceding(n, key, fingers, successors) == expected

    @given(nodes=st.lists(keys, min_size=1, max_size=30), key=keys, k=st.integers(0, 8))
    def test_successors_follow_the_ring_order(self, nodes: list[int], key: int, k: int) -> None:
        ring = SortedRing(nodes)
        succ = ring.successors(key, k)
        assert len(succ) == min(k, len(ring))
        assert len(set(succ)) == len(succ)
        if succ:
            assert succ[0] == ring.successor(key)
        for a, b in pairwise(succ):
            assert b == ring.successor((a + 1) % RING_SIZE)
