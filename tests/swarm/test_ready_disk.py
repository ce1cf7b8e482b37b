"""A group's members are recorded as its chunk's holders without the event loop
ever waiting for SQLite's write lock (`swarm/ready_disk.py`): while another
connection holds the lock (a worker installing a chunk), the record goes to a
worker, which writes the newest members once the lock is free. A real SQLite
file; the lock is held by a second connection of this test."""

from __future__ import annotations

import asyncio
import contextlib
import sqlite3
from collections.abc import Iterator
from pathlib import Path

import pytest

from mapapi.core.ids import ChunkId, PeerId
from mapapi.store import SqliteStore
from mapapi.swarm.ready_disk import ReadyDisk

TIMEOUT = 10.0
P, Q, R = sorted(PeerId.new() for _ in range(3))


@pytest.fixture
def store(tmp_path: Path) -> Iterator[SqliteStore]:
    made = SqliteStore(tmp_path / "s.sqlite", create=True)
    made.add_table("t", "google.protobuf.Struct")
    yield made
    made.close()


def _disk(store: SqliteStore) -> ReadyDisk:
    def unused(*_: object) -> None:
        raise AssertionError("no Ready is written here")

    return ReadyDisk(store, unused, unused)


@pytest.fixture
def chunk(store: SqliteStore) -> ChunkId:
    made = ChunkId.new()
    store.add_chunk(made, "t")
    return made


@contextlib.contextmanager
def locked(store: SqliteStore) -> Iterator[sqlite3.Connection]:
    """Another connection holding the store's write lock for the block."""
    con = sqlite3.connect(store.path, isolation_level=None, check_same_thread=False)
    con.execute("BEGIN IMMEDIATE")
    try:
        yield con
    finally:
        con.execute("COMMIT")
        con.close()


async def _written(disk: ReadyDisk, chunk: ChunkId) -> None:
    """Until the worker recording the chunk's holders is done."""
    async with asyncio.timeout(TIMEOUT):
        await disk._recording[chunk]


async def test_a_free_lock_records_the_holders_at_once(store: SqliteStore, chunk: ChunkId) -> None:
    _disk(store).holders(chunk, [P, Q])

    assert store.holders(chunk) == [P, Q]


async def test_a_taken_lock_hands_the_record_to_a_worker_which_writes_the_newest(
    store: SqliteStore, chunk: ChunkId
) -> None:
    disk = _disk(store)
    with locked(store) as other:
        disk.holders(chunk, [P])  # returns at once: the loop does not wait
        disk.holders(chunk, [P, Q, R])  # changed again before the worker got to it
        assert other.execute("SELECT COUNT(*) FROM holders").fetchone() == (0,)

    await _written(disk, chunk)
    assert store.holders(chunk) == [P, Q, R]


async def test_forgetting_a_group_waits_for_its_record_and_drops_the_rest(
    store: SqliteStore, chunk: ChunkId
) -> None:
    disk = _disk(store)
    forgotten = asyncio.Event()
    with locked(store):
        disk.holders(chunk, [P])
        await asyncio.sleep(0)  # sync-ok: one yield, so the worker takes P and waits for the lock
        disk.holders(chunk, [Q])  # the next, waiting for it
        disk.then(chunk, forgotten.set)  # the group is forgotten: Q is never written
        assert not forgotten.is_set()

    async with asyncio.timeout(TIMEOUT):
        await forgotten.wait()
    assert store.holders(chunk) == [P]
