"""The failure detector (swarm/failure.py; issue 7 §1)."""

import pytest

from mapapi.core.ids import PeerId
from mapapi.swarm.failure import FailureDetector, Health, Transition

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
