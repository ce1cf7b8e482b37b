"""Lamport logical clock (DESIGN §4)."""

from __future__ import annotations

import threading


class LamportClock:
    """A thread-safe Lamport clock.

    `tick()` stamps a local event, `merge()` folds in a time seen on a message
    (`max(local, remote) + 1`), `now()` reads without advancing.
    """

    def __init__(self, start: int = 0) -> None:
        if start < 0:
            raise ValueError(f"clock cannot start below 0, got {start}")
        self._time = start
        self._lock = threading.Lock()

    def now(self) -> int:
        """The current time, unchanged."""
        return self._time

    def tick(self) -> int:
        """Advance by one and return the new time."""
        with self._lock:
            self._time += 1
            return self._time

    def merge(self, remote: int) -> int:
        """Fold in a remote time: the clock becomes `max(local, remote) + 1`."""
        with self._lock:
            self._time = max(self._time, remote) + 1
            return self._time

    def advance_to(self, time: int) -> None:
        """Move forward to at least `time` without counting an event."""
        with self._lock:
            self._time = max(self._time, time)
