"""Lamport logical clock (DESIGN §4)."""

from __future__ import annotations

import threading

from mapapi.limits import LAMPORT_CEILING


class LamportClock:
    """A thread-safe Lamport clock.

    `tick()` stamps a local event, `merge()` folds in a time seen on a message
    (`max(local, remote) + 1`), `now()` reads without advancing. A time from
    elsewhere counts at most `limits.LAMPORT_CEILING`: a peer that sends an
    absurd time cannot push this clock to where its own messages would be
    refused (above `limits.MAX_LAMPORT`) or overflow.
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
            self._time = max(self._time, min(remote, LAMPORT_CEILING)) + 1
            return self._time

    def advance_to(self, time: int) -> None:
        """Move forward to at least `time` (at most `LAMPORT_CEILING`) without
        counting an event."""
        with self._lock:
            self._time = max(self._time, min(time, LAMPORT_CEILING))
