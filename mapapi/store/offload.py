"""Long reads and writes of a store, off the event loop (issue 14 §1).

A peer's heartbeats, lookups and protocol ticks are tasks of one asyncio loop:
a read of a whole mission or the install of a replica with 100,000 rows, run
on that loop, stops all of them for seconds, and the other peers suspect this
one. `off_loop` runs such a function in a worker thread instead (asyncio's
default executor), where the SQLite store gives it a connection of its own
(`sqlite_connection.Connections`: one per thread), and hands its result back to
the loop. SQLite serialises writers (`BEGIN IMMEDIATE`), so a write in a worker
and one on the loop never interleave; a short write on the loop waits while a
long one runs in a worker, but reads (WAL) never wait.

The function must not touch asyncio objects (futures, events, tasks, the
transport): it gets plain values and returns one. A `MemoryStore` is no more
thread-safe than a dict that the loop changes meanwhile, so with any store
but SQLite the function runs on the loop as before (the tests' stores, small).
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable
from contextlib import AbstractContextManager
from functools import partial
from typing import ParamSpec, TypeVar

from mapapi.store.sqlite import SqliteStore
from mapapi.store.sqlite_connection import WriteBusy

__all__ = ["WriteBusy", "off_loop", "without_waiting"]

P = ParamSpec("P")
T = TypeVar("T")


async def off_loop(store: object, fn: Callable[P, T], *args: P.args, **kwargs: P.kwargs) -> T:
    """`fn(*args, **kwargs)` run in a worker thread when `store` allows it (see
    the module docstring), else here; its result, or what it raised."""
    if isinstance(store, SqliteStore):
        return await asyncio.to_thread(_in_worker, store, partial(fn, *args, **kwargs))
    return fn(*args, **kwargs)


def _in_worker(store: SqliteStore, call: Callable[[], T]) -> T:
    # The store's `close` waits while the function runs (a peer closing meanwhile).
    with store.worker():
        return call()


def without_waiting(store: object) -> AbstractContextManager[None]:
    """A block whose writes to `store` raise `WriteBusy` instead of waiting for
    SQLite's write lock (held by a worker's long write): the loop then hands its
    write to a worker too. Other stores never wait long: a block as any other."""
    if isinstance(store, SqliteStore):
        return store.no_wait()
    return contextlib.nullcontext()
