"""Closing a store while a worker thread reads it (store/offload.py): `close` waits for
the worker, so a peer that stops during a long read does not crash SQLite."""

from __future__ import annotations

import asyncio
import threading
from pathlib import Path

from mapapi.store.offload import off_loop
from mapapi.store.sqlite import SqliteStore


async def test_close_waits_for_a_worker_reading_the_store(tmp_path: Path) -> None:
    store = SqliteStore(tmp_path / "s", create=True)
    started, release = threading.Event(), threading.Event()

    def long_read(s: SqliteStore) -> int:
        started.set()
        release.wait(10)
        return len(s.tables()) + s.clock()  # reads through this thread's connection

    reading = asyncio.create_task(off_loop(store, long_read, store))
    await asyncio.to_thread(started.wait, 10)
    closing = asyncio.create_task(asyncio.to_thread(store.close))
    await asyncio.sleep(0.05)  # sync-ok: closing must still be waiting (an absence)
    assert not closing.done()
    release.set()
    assert await reading == 0
    await closing
