"""Shared test configuration; the fixtures come from the `mapapi.testing` plugin.

A guard fails any test that synchronises with `time.sleep` / `asyncio.sleep`
(STYLE §7) unless the calling line is marked `# sync-ok`: tests await the event
that proves a state instead.
"""

import asyncio
import linecache
import os
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from hypothesis import settings

settings.register_profile("ci", deadline=None, derandomize=False, print_blob=True)
settings.register_profile("default", deadline=None)
settings.load_profile("ci" if os.environ.get("CI") else "default")

_TESTS = str(Path(__file__).resolve().parent)


@pytest.fixture(autouse=True)
def no_sleep_sync(monkeypatch: pytest.MonkeyPatch) -> Iterator[list[str]]:
    """Record sleeps called from test code; fail the test if any is unmarked."""
    calls: list[str] = []
    real_async, real_time = asyncio.sleep, time.sleep

    def check(delay: float) -> None:
        frame = sys._getframe(2)
        where = frame.f_code.co_filename
        marked = "# sync-ok" in linecache.getline(where, frame.f_lineno)
        if delay > 0 and where.startswith(_TESTS) and not marked:
            calls.append(f"{where}:{frame.f_lineno}")

    def async_sleep(delay: float, result: Any = None) -> Any:
        check(delay)
        return real_async(delay, result)

    def time_sleep(delay: float) -> None:
        check(delay)
        real_time(delay)

    monkeypatch.setattr(asyncio, "sleep", async_sleep)
    monkeypatch.setattr(time, "sleep", time_sleep)
    yield calls
    assert not calls, f"sleep used as synchronisation at {calls}; await an event instead"
