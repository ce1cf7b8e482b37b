"""The stall benchmark's report of CPU time the hypervisor stole (`mapbench.stall`):
computed from two `/proc/stat` readings, None where there are none."""

from __future__ import annotations

from pathlib import Path

from mapbench.stall import _cpu_times, _steal_percent


def test_steal_is_the_share_of_the_cpu_time_between_two_readings() -> None:
    before = [100, 0, 50, 800, 0, 0, 0, 50]
    after = [400, 0, 100, 1400, 0, 0, 0, 100]  # 1,000 ticks more, 50 of them stolen
    assert _steal_percent(before, after) == 5.0


def test_no_reading_or_no_time_between_gives_none() -> None:
    reading = [1, 2, 3, 4, 5, 6, 7, 8]
    assert _steal_percent(None, reading) is None
    assert _steal_percent(reading, None) is None
    assert _steal_percent(reading, reading) is None


def test_this_machine_is_read_as_eight_counters() -> None:
    times = _cpu_times()
    if not Path("/proc/stat").exists():  # not Linux: nothing to read
        assert times is None
        return
    assert times is not None
    assert len(times) == 8
    assert all(t >= 0 for t in times)
