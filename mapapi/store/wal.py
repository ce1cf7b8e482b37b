"""Checkpoints of a peer's SQLite write-ahead log, in a worker thread (issue 14 §1, §4).

The event loop's connection does not checkpoint (`Connections.no_wait`): the
commit that crossed SQLite's threshold copied the whole log into the file, and
after a snapshot install that was tens of milliseconds on the loop. Worker
threads' commits still checkpoint; `WalKeeper` checkpoints every `EVERY`
seconds as well, so a peer whose writes are all small ones on the loop keeps
its log, and its disk, bounded too (cut back to `WAL_LIMIT_BYTES`).
"""

from __future__ import annotations

import asyncio
import logging

from mapapi.core.errors import MapError
from mapapi.store.offload import off_loop
from mapapi.store.sqlite import SqliteStore

log = logging.getLogger(__name__)

EVERY = 2.0
"""Seconds between two checkpoints."""


class WalKeeper:
    """Checkpoints `store`'s log every `every` seconds (any other store: nothing)."""

    def __init__(self, store: object, every: float = EVERY) -> None:
        self.store = store
        self.every = every
        self._task: asyncio.Task[None] | None = None
        self.checkpointed = asyncio.Event()  # set after each checkpoint

    def start(self) -> None:
        """Start checkpointing (on the running loop)."""
        if isinstance(self.store, SqliteStore):
            self._task = asyncio.get_running_loop().create_task(self._run(), name="wal")

    async def _run(self) -> None:
        assert isinstance(self.store, SqliteStore)
        while True:
            await asyncio.sleep(self.every)
            try:
                await off_loop(self.store, self.store.checkpoint)
                self.checkpointed.set()
            except MapError as exc:  # a full disk: said, and tried again later
                log.warning("checkpoint of %s failed: %s", self.store.path, exc)

    async def close(self) -> None:
        """Stop checkpointing (one under way in its thread ends alone)."""
        task, self._task = self._task, None
        if task is not None:
            task.cancel()
            await asyncio.gather(task, return_exceptions=True)
