"""The failure detector and the quorum rule (swarm/failure.py, swarm/quorum.py; issue 7 §1)."""

import itertools

import pytest
from hypothesis import given
from hypothesis import strategies as st

from mapapi.core.ids import PeerId
from mapapi.swarm.failure import FailureDetector, Health, Transition
from mapapi.swarm.quorum import is_quorum

A, B, C, D, E = (PeerId(f"{i:032x}") for i in range(1, 6))


class TestFailureDetector:
    def test_a_watched_peer_starts_alive(self) -> None:
        detector = FailureDetector(1.0, 2.0)
        detector.watch(A, now=10.0)
        assert detector.health(A) is Health.ALIVE
        assert detector.tick(10.5) == []

    def test_silence_makes_a_peer_suspect_then_dead(self) -> None:
        detector = FailureDetector(1.0, 2.0)
        detector.watch(A, now=0.0)
        assert detector.tick(1.0) == [Transition(A, Health.ALIVE, Health.SUSPECT)]
        assert detector.tick(1.5) == []
        assert detector.tick(2.0) == [Transition(A, Health.SUSPECT, Health.DEAD)]
        assert detector.health(A) is Health.DEAD

    def test_a_long_silence_goes_straight_to_dead(self) -> None:
        detector = FailureDetector(1.0, 2.0)
        detector.watch(A, now=0.0)
        assert detector.tick(7.0) == [Transition(A, Health.ALIVE, Health.DEAD)]

    def test_any_message_brings_a_peer_back(self) -> None:
        detector = FailureDetector(1.0, 2.0)
        detector.watch(A, now=0.0)
        detector.tick(5.0)
        assert detector.heard(A, 5.1) == Transition(A, Health.DEAD, Health.ALIVE)
        assert detector.tick(5.5) == []
        assert detector.heard(A, 5.6) is None  # alive already: no transition

    def test_hearing_keeps_a_peer_alive(self) -> None:
        detector = FailureDetector(1.0, 2.0)
        detector.watch(A, now=0.0)
        for now in (0.9, 1.8, 2.7, 3.6):
            detector.heard(A, now)
            assert detector.tick(now + 0.5) == []

    def test_an_old_message_does_not_move_time_back(self) -> None:
        detector = FailureDetector(1.0, 2.0)
        detector.watch(A, now=5.0)
        detector.heard(A, 1.0)
        assert detector.silent_for(A, 5.5) == pytest.approx(0.5)

    def test_unwatched_peers_count_as_alive_and_are_not_ticked(self) -> None:
        detector = FailureDetector(1.0, 2.0)
        assert detector.health(B) is Health.ALIVE
        assert detector.heard(B, 1.0) is None
        detector.watch(A, now=0.0)
        detector.unwatch(A)
        assert detector.tick(10.0) == []
        assert detector.watched() == []

    def test_watch_twice_keeps_the_first_time(self) -> None:
        detector = FailureDetector(1.0, 2.0)
        detector.watch(A, now=0.0)
        detector.watch(A, now=1.9)
        assert detector.tick(2.0) == [Transition(A, Health.ALIVE, Health.DEAD)]

    def test_transitions_come_in_id_order(self) -> None:
        detector = FailureDetector(1.0, 2.0)
        for peer in (C, A, B):
            detector.watch(peer, now=0.0)
        assert [t.peer for t in detector.tick(3.0)] == [A, B, C]

    @pytest.mark.parametrize(("suspect", "dead"), [(0.0, 1.0), (2.0, 1.0), (-1.0, 1.0)])
    def test_bad_thresholds_are_refused(self, suspect: float, dead: float) -> None:
        with pytest.raises(ValueError, match="suspect_after"):
            FailureDetector(suspect, dead)


class TestQuorum:
    def test_a_strict_majority_is_a_quorum(self) -> None:
        assert is_quorum({A, B, C}, [A, B, C, D, E])
        assert is_quorum({C, D, E}, [A, B, C, D, E])
        assert not is_quorum({D, E}, [A, B, C, D, E])

    def test_half_is_a_quorum_only_with_the_lowest_holder(self) -> None:
        assert is_quorum({A}, [A, B])
        assert not is_quorum({B}, [A, B])
        assert is_quorum({A, D}, [A, B, C, D])
        assert not is_quorum({B, C}, [A, B, C, D])

    def test_a_lone_holder_is_its_own_quorum(self) -> None:
        assert is_quorum({A}, [A])

    def test_strangers_do_not_count(self) -> None:
        assert not is_quorum({A, D, E}, [A, B, C])
        assert not is_quorum({A}, [])

    @given(st.integers(1, 7), st.data())
    def test_two_quorums_always_share_a_holder(self, n: int, data: st.DataObject) -> None:
        holders = [PeerId(f"{i:032x}") for i in range(1, n + 1)]
        subsets = [set(s) for r in range(n + 1) for s in itertools.combinations(holders, r)]
        quorums = [s for s in subsets if is_quorum(s, holders)]
        first = data.draw(st.sampled_from(quorums))
        second = data.draw(st.sampled_from(quorums))
        assert first & second

    @given(st.integers(1, 7))
    def test_of_two_disjoint_sides_at_most_one_is_a_quorum(self, n: int) -> None:
        holders = [PeerId(f"{i:032x}") for i in range(1, n + 1)]
        for r in range(n + 1):
            for side in itertools.combinations(holders, r):
                other = set(holders) - set(side)
                assert not (is_quorum(side, holders) and is_quorum(other, holders))


class TestPauses:
    def test_a_pause_of_this_process_is_nobodys_silence(self) -> None:
        detector = FailureDetector(1.0, 2.0, pause_after=0.5)
        detector.watch(A, now=0.0)
        detector.tick(0.4)
        assert detector.tick(5.0) == []  # the loop stood still for 4.6 s
        assert detector.health(A) is Health.ALIVE
        assert detector.tick(5.3) == []
        assert detector.tick(5.6) == [Transition(A, Health.ALIVE, Health.SUSPECT)]

    def test_regular_ticks_still_see_silence(self) -> None:
        detector = FailureDetector(1.0, 2.0, pause_after=0.5)
        detector.watch(A, now=0.0)
        changes = [c for t in range(1, 11) for c in detector.tick(t * 0.25)]
        assert changes == [
            Transition(A, Health.ALIVE, Health.SUSPECT),
            Transition(A, Health.SUSPECT, Health.DEAD),
        ]
