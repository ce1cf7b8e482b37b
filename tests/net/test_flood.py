"""Bounded memory under a flood of large messages (issue 18 §5), on real processes.

A real peer process is flooded by sender processes (`mapbench.flood`): with one
huge frame each (the probe: libzmq now cuts such a frame on its header) and with
messages in parts (the reassembly budget refuses what does not fit). The peer
must answer every ping throughout and stay under the 300 MB the issue allows.
The flood is smaller than `mapctl bench flood`'s 20 x 120 MB (docs/benchmarks.md)
so that it fits `make test`.
"""

from __future__ import annotations

import pytest

from mapapi.core import limits
from mapbench.flood import run_flood

pytestmark = pytest.mark.slow

BUDGET_MB = 300


def test_one_huge_frame_per_sender_is_cut_before_it_is_held() -> None:
    report = run_flood(senders=6, megabytes=100, mode="frame", settle=0.5)
    assert report.pings >= 1  # each answered (run_flood fails on a missed ping)
    assert report.rss_peak_mb < BUDGET_MB
    # before the cap, the peer held each frame whole: 6 x 100 MB over its idle size
    assert report.rss_peak_mb - report.rss_idle_mb < 100


def test_messages_in_parts_beyond_the_budget_are_refused() -> None:
    each = limits.MAX_BUFFERED_BYTES // 2**20 // 2 + 8  # two never fit the budget at once
    report = run_flood(senders=6, megabytes=each, mode="parts", settle=0.5)
    assert report.rss_peak_mb < BUDGET_MB
    assert report.parts_peak_mb <= limits.MAX_BUFFERED_BYTES / 2**20
    assert report.dropped.get("over-budget", 0) >= 1
