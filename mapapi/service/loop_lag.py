"""How late the peer daemon's event loop runs (issue 14 §1): `peer status` shows it.

Heartbeats, Chord's stabilisation and the failure detector's rounds are tasks of
one asyncio loop; anything that holds the loop (a long SQLite read, decoding a
mission, drawing a plot) delays them all, and other peers suspect a peer whose
loop stalls for `SUSPECT_AFTER` (1.5 s). `LoopLag` is a task that sleeps
`PERIOD` seconds again and again and records how late it woke, in a `LagRing`
that keeps the last `WINDOW` seconds; `summary()` gives p50, p99 and max in ms.

One late wake-up stands for every tick the stall swallowed: a wake-up `L`
seconds late also records `L - PERIOD`, `L - 2 * PERIOD` ... down to 0, the
lateness a timer due at each of those ticks would have seen. The percentiles are
thus over time, not over wake-ups: a 2 s stall in a minute is 3 % of the samples
(it moves p99), not one sample in 1,200.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
from collections import deque
from dataclasses import dataclass

log = logging.getLogger(__name__)

PERIOD = 0.05
"""Seconds between two wake-ups of the watch (20 a second: about 1 ms of CPU per second)."""

WINDOW = 60.0
"""Seconds of samples kept: `peer status` reports the last minute."""

STALL_WARNING = 0.5
"""A stall at least this long (seconds) is logged as a warning in `peer.log`."""


@dataclass(frozen=True, slots=True)
class LagSummary:
    """The loop's lateness over the window, in milliseconds."""

    p50: float
    p99: float
    max: float

    def as_json(self) -> dict[str, float]:
        """`{"p50": ms, "p99": ms, "max": ms}`, as `peer status --json` shows it."""
        return {"p50": self.p50, "p99": self.p99, "max": self.max}


class LagRing:
    """The lateness samples of the last `window` seconds (pure: times are given).

    At most `window / period` samples are kept (a bounded ring), each with the
    time it was taken; older ones are dropped when a summary is asked for.
    """

    def __init__(self, window: float = WINDOW, period: float = PERIOD) -> None:
        self.window = window
        self.period = period
        self._samples: deque[tuple[float, float]] = deque(maxlen=math.ceil(window / period))

    def __len__(self) -> int:
        """How many samples are kept (some may be older than the window)."""
        return len(self._samples)

    def record(self, now: float, late: float) -> None:
        """A wake-up `late` seconds after it was due, at time `now` (see the module
        docstring: each tick the stall swallowed is recorded too)."""
        late = max(0.0, late)
        missed = min(int(late / self.period), self._samples.maxlen or 0)
        for k in range(missed, 0, -1):
            self._samples.append((now, late - k * self.period))
        self._samples.append((now, late))

    def summary(self, now: float) -> LagSummary:
        """p50, p99 and max over the samples of the last `window` seconds before
        `now`, in milliseconds (all 0 before the first sample)."""
        while self._samples and self._samples[0][0] < now - self.window:
            self._samples.popleft()
        lags = sorted(late for _, late in self._samples)
        if not lags:
            return LagSummary(0.0, 0.0, 0.0)

        def rank(q: float) -> float:  # nearest rank
            return round(1000 * lags[min(len(lags) - 1, math.ceil(q * len(lags)) - 1)], 1)

        return LagSummary(rank(0.50), rank(0.99), round(1000 * lags[-1], 1))


class LoopLag:
    """The watch over the running event loop (see the module docstring).

    Args:
        period: seconds between two wake-ups.
        window: seconds of samples kept.
    """

    def __init__(self, period: float = PERIOD, window: float = WINDOW) -> None:
        self.period = period
        self.ring = LagRing(window, period)
        self._task: asyncio.Task[None] | None = None

    def start(self) -> None:
        """Start watching the running loop."""
        self._task = asyncio.get_running_loop().create_task(self._run(), name="loop-lag")

    def summary(self) -> LagSummary:
        """The lateness over the last window, in milliseconds."""
        return self.ring.summary(asyncio.get_running_loop().time())

    async def _run(self) -> None:
        loop = asyncio.get_running_loop()
        while True:
            due = loop.time() + self.period
            await asyncio.sleep(self.period)
            now = loop.time()
            late = now - due
            self.ring.record(now, late)
            if late >= STALL_WARNING:
                log.warning("the event loop was blocked for %.2f s (heartbeats were late)", late)

    async def close(self) -> None:
        """Stop watching."""
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
            self._task = None
