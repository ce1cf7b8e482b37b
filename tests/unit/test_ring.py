"""Chord id arithmetic (mapapi.lookup.dht.ring, DESIGN §7)."""

from __future__ import annotations

import hashlib

import pytest

from mapapi.core.ids import ChunkId, PeerId
from mapapi.lookup.dht.ring import (
    RING_BITS,
    RING_SIZE,
    Hop,
    SortedRing,
    chunk_key,
    closest_preceding,
    distance,
    finger_start,
    in_interval,
    next_hop,
    peer_key,
    responsible,
)

TOP = RING_SIZE - 1


class TestKeys:
    def test_ring_is_160_bits(self) -> None:
        assert RING_BITS == 160
        assert RING_SIZE == 2**160

    def test_peer_key_is_sha1_of_the_id_bytes(self) -> None:
        peer = PeerId("00112233445566778899aabbccddeeff")
        digest = hashlib.sha1(bytes.fromhex(peer)).digest()
        assert peer_key(peer) == int.from_bytes(digest, "big")

    def test_chunk_key_is_sha1_of_the_id_bytes(self) -> None:
        chunk = ChunkId("ffeeddccbbaa99887766554433221100")
        digest = hashlib.sha1(bytes.fromhex(chunk)).digest()
        assert chunk_key(chunk) == int.from_bytes(digest, "big")

    def test_keys_spread_over_the_whole_ring(self) -> None:
        keys = [peer_key(PeerId.new()) for _ in range(64)]
        assert len(set(keys)) == 64
        assert max(keys).bit_length() > 150

    def test_distance_is_clockwise_and_wraps(self) -> None:
        assert distance(3, 10) == 7
        assert distance(10, 3) == RING_SIZE - 7
        assert distance(TOP, 0) == 1
        assert distance(5, 5) == 0

    @pytest.mark.parametrize("bad", [-1, RING_SIZE, 2**200, 1.0, True, "7"])
    def test_non_keys_are_rejected(self, bad: object) -> None:
        with pytest.raises(ValueError, match="ring key"):
            distance(bad, 0)  # type: ignore[arg-type]
        with pytest.raises(ValueError, match="ring key"):
            in_interval(0, 1, bad, inclusive_right=True)  # type: ignore[arg-type]


class TestInInterval:
    @pytest.mark.parametrize(
        ("x", "a", "b", "open_", "half_open"),
        [
            (5, 3, 10, True, True),
            (3, 3, 10, False, False),  # the left end is never in
            (10, 3, 10, False, True),  # the right end only when inclusive
            (11, 3, 10, False, False),
            (2, 3, 10, False, False),
            # wrapping past zero: (TOP-1, 2)
            (TOP, TOP - 1, 2, True, True),
            (0, TOP - 1, 2, True, True),
            (2, TOP - 1, 2, False, True),
            (TOP - 1, TOP - 1, 2, False, False),
            (3, TOP - 1, 2, False, False),
            (TOP - 2, TOP - 1, 2, False, False),
            # equal endpoints: the whole ring, less the end when open
            (7, 7, 7, False, True),
            (8, 7, 7, True, True),
            (6, 7, 7, True, True),
            (0, 0, 0, False, True),
            (TOP, 0, 0, True, True),
            # adjacent endpoints: nothing fits in the open interval
            (4, 3, 4, False, True),
            (0, TOP, 0, False, True),
        ],
    )
    def test_intervals(self, x: int, a: int, b: int, open_: bool, half_open: bool) -> None:
        assert in_interval(x, a, b, inclusive_right=False) is open_
        assert in_interval(x, a, b, inclusive_right=True) is half_open

    def test_inclusive_right_must_be_named(self) -> None:
        with pytest.raises(TypeError):
            in_interval(1, 0, 2, True)  # type: ignore[misc]


class TestFingerStart:
    def test_powers_of_two_past_the_node(self) -> None:
        assert [finger_start(100, i) for i in range(4)] == [101, 102, 104, 108]
        assert finger_start(0, RING_BITS - 1) == 2**159

    def test_wraps_past_zero(self) -> None:
        assert finger_start(TOP, 0) == 0
        assert finger_start(TOP, 3) == 7
        assert finger_start(2**159, RING_BITS - 1) == 0

    @pytest.mark.parametrize("i", [-1, RING_BITS, 1.0])
    def test_index_must_be_in_range(self, i: int) -> None:
        with pytest.raises(ValueError, match="finger index"):
            finger_start(0, i)


class TestClosestPreceding:
    def test_picks_the_candidate_nearest_before_the_key(self) -> None:
        assert closest_preceding(10, 100, [20, 40, 80, 120, 500], []) == 80

    def test_order_and_duplicates_do_not_matter(self) -> None:
        assert closest_preceding(10, 100, [80, 500, 20, 80, 40], [20]) == 80

    def test_a_candidate_on_the_key_does_not_precede_it(self) -> None:
        assert closest_preceding(10, 100, [20, 100], []) == 20

    def test_without_candidates_before_the_key_it_is_the_node_itself(self) -> None:
        assert closest_preceding(10, 15, [20, 40], [20]) == 10
        assert closest_preceding(10, 100, [], []) == 10
        assert closest_preceding(10, 100, [None, None], []) == 10

    def test_unfilled_fingers_are_skipped(self) -> None:
        assert closest_preceding(10, 100, [None, 30, None], []) == 30

    def test_successor_list_entries_count(self) -> None:
        assert closest_preceding(10, 100, [20], [30, 60, 200]) == 60

    def test_the_node_itself_is_not_a_candidate(self) -> None:
        assert closest_preceding(10, 100, [10, 10], [10]) == 10

    def test_wraps_past_zero(self) -> None:
        assert closest_preceding(TOP - 10, 50, [TOP - 5, 3, 40, 60], []) == 40
        assert closest_preceding(TOP - 10, 2, [TOP - 5, 3, 40], []) == TOP - 5

    def test_key_on_the_node_means_all_the_way_round(self) -> None:
        # (n, n) is the ring less n: the farthest known node, i.e. n's predecessor
        assert closest_preceding(10, 10, [20, 5, 900], []) == 5


class TestNextHop:
    def test_key_up_to_the_successor_is_answered(self) -> None:
        assert next_hop(10, 15, [20, 30], [20, 40]) == Hop(20, final=True)
        assert next_hop(10, 20, [20, 30], [20, 40]) == Hop(20, final=True)

    def test_key_past_the_successor_is_forwarded(self) -> None:
        assert next_hop(10, 50, [20, 30], [20, 40, 80]) == Hop(40, final=False)

    def test_forwards_to_the_successor_when_fingers_are_empty(self) -> None:
        assert next_hop(10, 50, [20], [None] * RING_BITS) == Hop(20, final=False)

    def test_successor_list_shortens_the_route(self) -> None:
        assert next_hop(10, 50, [20, 30, 45], [20, None]) == Hop(45, final=False)

    def test_key_on_the_node_itself_goes_round(self) -> None:
        assert next_hop(10, 10, [20], [20, 5]) == Hop(5, final=False)

    def test_single_node_answers_everything_itself(self) -> None:
        for key in (0, 10, 11, TOP):
            assert next_hop(10, key, [10], [10] * RING_BITS) == Hop(10, final=True)

    def test_wrap_around(self) -> None:
        assert next_hop(TOP - 1, 0, [5], [5]) == Hop(5, final=True)
        assert next_hop(TOP - 1, TOP, [5], [5]) == Hop(5, final=True)

    def test_needs_a_successor(self) -> None:
        with pytest.raises(ValueError, match="successor"):
            next_hop(10, 50, [], [20])


class TestResponsible:
    def test_keys_after_the_predecessor_up_to_the_node(self) -> None:
        assert responsible(15, 20, 10)
        assert responsible(20, 20, 10)  # a key exactly on the node is the node's
        assert not responsible(10, 20, 10)  # ... and not its successor's
        assert not responsible(25, 20, 10)

    def test_wraps_past_zero(self) -> None:
        assert responsible(TOP, 5, TOP - 3)
        assert responsible(0, 5, TOP - 3)
        assert not responsible(6, 5, TOP - 3)

    def test_a_single_node_stores_every_key(self) -> None:
        assert all(responsible(k, 42, 42) for k in (0, 41, 42, 43, TOP))


class TestSortedRing:
    ring = SortedRing([300, 100, 200, 100])

    def test_nodes_are_sorted_and_unique(self) -> None:
        assert self.ring.nodes == (100, 200, 300)
        assert len(self.ring) == 3
        assert list(self.ring) == [100, 200, 300]
        assert 200 in self.ring
        assert 201 not in self.ring
        assert "200" not in self.ring

    def test_needs_a_node(self) -> None:
        with pytest.raises(ValueError, match="at least one node"):
            SortedRing([])

    def test_rejects_non_keys(self) -> None:
        with pytest.raises(ValueError, match="ring node"):
            SortedRing([1, RING_SIZE])

    def test_successor(self) -> None:
        assert self.ring.successor(150) == 200
        assert self.ring.successor(200) == 200  # on a node: that node
        assert self.ring.successor(301) == 100  # wraps
        assert self.ring.successor(0) == 100
        assert self.ring.successor(TOP) == 100

    def test_predecessor(self) -> None:
        assert self.ring.predecessor(150) == 100
        assert self.ring.predecessor(200) == 100  # strictly before
        assert self.ring.predecessor(100) == 300  # wraps
        assert self.ring.predecessor(0) == 300
        assert self.ring.predecessor(TOP) == 300

    def test_key_lies_between_predecessor_and_successor(self) -> None:
        for key in (0, 99, 100, 101, 250, 300, TOP):
            pred, succ = self.ring.predecessor(key), self.ring.successor(key)
            assert in_interval(key, pred, succ, inclusive_right=True)
            assert responsible(key, succ, self.ring.predecessor(succ))

    def test_successors(self) -> None:
        assert self.ring.successors(150, 2) == [200, 300]
        assert self.ring.successors(250, 3) == [300, 100, 200]
        assert self.ring.successors(250, 10) == [300, 100, 200]  # capped, no repeats
        assert self.ring.successors(250, 0) == []
        with pytest.raises(ValueError, match="k must be"):
            self.ring.successors(0, -1)

    def test_successor_list_excludes_the_node(self) -> None:
        assert self.ring.successor_list(100, 4) == [200, 300]
        assert self.ring.successor_list(300, 1) == [100]
        with pytest.raises(ValueError, match="not a node"):
            self.ring.successor_list(150, 4)
        with pytest.raises(ValueError, match="at least 1"):
            self.ring.successor_list(100, 0)

    def test_finger_table(self) -> None:
        fingers = self.ring.finger_table(100)
        assert len(fingers) == RING_BITS
        assert fingers[:7] == [200] * 7  # 101 .. 164
        assert fingers[7] == 300  # 228
        assert fingers[8:] == [100] * (RING_BITS - 8)  # 356 and beyond wrap to 100

    def test_single_node_ring(self) -> None:
        ring = SortedRing([42])
        for key in (0, 41, 42, 43, TOP):
            assert ring.successor(key) == ring.predecessor(key) == 42
        assert ring.successors(0, 4) == [42]
        assert ring.successor_list(42, 4) == [42]
        assert set(ring.finger_table(42)) == {42}

    def test_nodes_at_both_ends_of_the_key_space(self) -> None:
        ring = SortedRing([0, TOP])
        assert ring.successor(1) == TOP
        assert ring.successor(TOP) == TOP
        assert ring.predecessor(0) == TOP
        assert ring.successor_list(TOP, 4) == [0]
