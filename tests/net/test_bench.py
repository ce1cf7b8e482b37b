"""The round-trip measurement runs (its figures are reported, never asserted)."""

from __future__ import annotations

import pytest

from mapbench.net import measure_round_trip, summarize


async def test_measure_round_trip_in_process() -> None:
    result = await measure_round_trip(20, warmup=5)
    assert result.label == "rpc-in-process"
    assert result.n == 20
    assert 0 < result.p50_us <= result.p99_us


async def test_measure_round_trip_over_curve() -> None:
    result = await measure_round_trip(20, warmup=5, secure=True)
    assert result.label == "rpc-secure-in-process"
    assert result.n == 20


def test_summarize_percentiles() -> None:
    result = summarize("x", [i / 1e6 for i in range(1, 101)])
    assert (result.p50_us, result.p99_us) == (pytest.approx(51), pytest.approx(100))
    with pytest.raises(ValueError, match="no samples"):
        summarize("x", [])
