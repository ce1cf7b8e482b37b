"""The Lamport clock (mapapi.core.clock, DESIGN §4)."""

import threading

import pytest

from mapapi.core.clock import LamportClock


class TestLamportClock:
    def test_starts_at_zero_by_default(self) -> None:
        assert LamportClock().now() == 0

    def test_starts_where_told(self) -> None:
        assert LamportClock(41).now() == 41

    def test_refuses_negative_start(self) -> None:
        with pytest.raises(ValueError, match="below 0"):
            LamportClock(-1)

    def test_now_does_not_advance(self) -> None:
        clock = LamportClock(5)
        assert clock.now() == clock.now() == 5

    def test_tick_advances_by_one_and_returns_new_time(self) -> None:
        clock = LamportClock(5)
        assert clock.tick() == 6
        assert clock.tick() == 7
        assert clock.now() == 7

    def test_merge_of_a_later_time_jumps_past_it(self) -> None:
        clock = LamportClock(3)
        assert clock.merge(10) == 11
        assert clock.now() == 11

    def test_merge_of_an_earlier_time_still_counts_an_event(self) -> None:
        clock = LamportClock(10)
        assert clock.merge(3) == 11

    def test_merge_of_an_equal_time(self) -> None:
        clock = LamportClock(7)
        assert clock.merge(7) == 8

    def test_receive_happens_after_send(self) -> None:
        sender, receiver = LamportClock(), LamportClock(2)
        sent = sender.tick()
        received = receiver.merge(sent)
        assert received > sent
        assert received > 2

    def test_advance_to_moves_forward_without_an_event(self) -> None:
        clock = LamportClock(4)
        clock.advance_to(9)
        assert clock.now() == 9
        clock.advance_to(9)
        assert clock.now() == 9

    def test_advance_to_never_goes_back(self) -> None:
        clock = LamportClock(9)
        clock.advance_to(2)
        assert clock.now() == 9

    def test_concurrent_ticks_are_all_counted_and_unique(self) -> None:
        clock = LamportClock()
        seen: list[list[int]] = [[] for _ in range(8)]

        def work(out: list[int]) -> None:
            for _ in range(2000):
                out.append(clock.tick())

        threads = [threading.Thread(target=work, args=(out,)) for out in seen]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        stamps = [s for out in seen for s in out]
        assert clock.now() == 16000
        assert sorted(stamps) == list(range(1, 16001))
