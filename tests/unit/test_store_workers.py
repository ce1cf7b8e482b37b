"""A store's worker threads (store/offload.py): `close` waits for a worker still
reading, so a peer that stops during a long read does not crash SQLite; a write
that must not wait for a worker's lock says so at once (`without_waiting`); and
checkpoints cut the write-ahead log back (store/wal.py)."""

from __future__ import annotations

import asyncio
import threading
from pathlib import Path

import pytest

from mapapi.core.ids import ChunkId
from mapapi.store import sqlite_connection
from mapapi.store.base import LogRow
from mapapi.store.offload import WriteBusy, off_loop, without_waiting
from mapapi.store.sqlite import SqliteStore
from mapapi.store.wal import WalKeeper


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


def test_a_write_that_would_wait_for_the_lock_says_so_and_writes_nothing(tmp_path: Path) -> None:
    store = SqliteStore(tmp_path / "s", create=True)
    chunk = ChunkId.new()
    holding, release = threading.Event(), threading.Event()

    def hold() -> None:
        with store.exclusive():  # a worker's long write
            holding.set()
            release.wait(10)

    worker = threading.Thread(target=hold)
    worker.start()
    try:
        assert holding.wait(10)
        with pytest.raises(WriteBusy), without_waiting(store):
            store.raft_save(chunk, hard=(1, 0, 0))
        assert store.raft_load(chunk) is None
    finally:
        release.set()
        worker.join(10)
    with without_waiting(store):  # free again: it writes
        store.raft_save(chunk, hard=(2, 0, 0))
    kept = store.raft_load(chunk)
    assert kept is not None
    assert kept.term == 2
    store.close()


async def test_the_keeper_checkpoints_so_the_log_starts_over(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(sqlite_connection, "WAL_LIMIT_BYTES", 0)  # cut back to nothing: seen
    store = SqliteStore(tmp_path / "s", create=True)
    wal = tmp_path / "s-wal"
    with without_waiting(store):  # the loop's connection: it never checkpoints
        for _ in range(300):
            store.raft_save(ChunkId.new(), hard=(1, 0, 0), entries=[LogRow(1, 1, 0, bytes(20_000))])
    grown = wal.stat().st_size
    keeper = WalKeeper(store, every=0.01)
    keeper.start()
    try:
        async with asyncio.timeout(10):
            await keeper.checkpointed.wait()
    finally:
        await keeper.close()
    with without_waiting(store):  # the next write starts the log over, cut back
        store.raft_save(ChunkId.new(), hard=(1, 0, 0))

    assert grown > 6_000_000  # past SQLite's own threshold: 300 writes of 20 kB
    assert wal.stat().st_size < 100_000
    store.close()
