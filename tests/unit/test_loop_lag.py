"""How late the event loop runs (mapapi.service.loop_lag): the ring of samples
over the last minute, and the watch over a real loop."""

from __future__ import annotations

import asyncio
import time

import pytest

from mapapi.service.loop_lag import LagRing, LagSummary, LoopLag


class TestLagRing:
    def test_no_sample_reads_zero(self) -> None:
        assert LagRing().summary(0.0) == LagSummary(0.0, 0.0, 0.0)

    def test_percentiles_are_nearest_rank_in_ms(self) -> None:
        ring = LagRing(window=60.0, period=0.1)
        for i in range(100):
            ring.record(i * 0.1, 0.0005 * (i + 1))  # 0.5 .. 50 ms, none late by a period
        assert ring.summary(10.0) == LagSummary(25.0, 49.5, 50.0)

    def test_a_stall_counts_every_tick_it_swallowed(self) -> None:
        ring = LagRing(window=60.0, period=0.05)
        for i in range(200):
            ring.record(i * 0.05, 0.0)
        ring.record(10.0, 0.5)  # 10 periods late: the ticks it swallowed were 0.05 .. 0.45 late

        lags = ring.summary(10.0)

        assert lags.max == 500.0
        assert lags.p99 == pytest.approx(400.0)  # the 209th of 211 samples
        assert lags.p50 == 0.0

    def test_samples_older_than_the_window_are_dropped(self) -> None:
        ring = LagRing(window=60.0, period=0.05)
        ring.record(0.0, 2.0)
        ring.record(61.0, 0.002)
        assert ring.summary(61.0) == LagSummary(2.0, 2.0, 2.0)

    def test_the_ring_is_bounded(self) -> None:
        ring = LagRing(window=1.0, period=0.1)
        ring.record(0.0, 100.0)  # a 100 s stall would be 1,000 ticks: 10 are kept
        for _ in range(10):
            ring.record(0.5, 0.0)
        assert ring.summary(0.5).max == 0.0


async def test_the_watch_sees_a_blocked_loop() -> None:
    lag = LoopLag(period=0.01)
    lag.start()
    try:
        await asyncio.sleep(0)  # sync-ok: a yield; the watch starts its first sleep
        time.sleep(0.2)  # noqa: ASYNC251  # sync-ok: the stall the watch must see
        for _ in range(100):  # the overdue wake-up runs within a few turns of the loop
            if len(lag.ring):
                break
            await asyncio.sleep(0)  # sync-ok: a yield, not a wait
        seen = lag.summary()
    finally:
        await lag.close()
    assert seen.max >= 190.0
    assert len(lag.ring) >= 19  # the wake-up and the 18 or 19 ticks the stall swallowed
