"""A blocking facade over the async `Peer`, for scripts and threads.

`open_peer(path)` starts an event loop in a background thread and returns a
proxy: every method call runs on that loop and blocks until done; coroutines
are awaited there, and a returned `Transaction` comes back wrapped the same
way, so `tx.get(...)` and `tx.commit()` block too. Calls from many threads are
safe: they all execute on the one loop.
"""

from __future__ import annotations

import asyncio
import inspect
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

from mapapi import app
from mapapi.core.errors import ConflictError
from mapapi.core.transaction import Transaction
from mapapi.service.peer import Peer

_WRAPPED = (Peer, Transaction)


class _LoopThread:
    """An event loop running forever in a daemon thread."""

    def __init__(self) -> None:
        self.loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self._thread.start()

    def call(self, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
        async def run() -> Any:
            result = fn(*args, **kwargs)
            return await result if inspect.isawaitable(result) else result

        return asyncio.run_coroutine_threadsafe(run(), self.loop).result()

    def stop(self) -> None:
        self.loop.call_soon_threadsafe(self.loop.stop)
        self._thread.join()
        self.loop.close()


class Blocking:
    """Proxy of a `Peer` or `Transaction` whose methods block (see module doc)."""

    def __init__(self, target: Any, runner: _LoopThread) -> None:
        self._target = target
        self._runner = runner

    def __getattr__(self, name: str) -> Any:
        value = getattr(self._target, name)
        if not callable(value):
            return value

        def call(*args: Any, **kwargs: Any) -> Any:
            try:
                result = self._runner.call(value, *args, **kwargs)
            except ConflictError as err:
                raise _BlockingConflict(err, self._runner) from err
            return Blocking(result, self._runner) if isinstance(result, _WRAPPED) else result

        return call

    def close(self) -> None:
        """Close the peer (if this wraps one) and stop the loop thread."""
        if isinstance(self._target, Peer):
            self._runner.call(self._target.close)
            self._runner.stop()

    def __enter__(self) -> Blocking:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class _BlockingConflict(ConflictError):
    """A `ConflictError` whose `merge()` returns a blocking transaction too."""

    def __init__(self, err: ConflictError, runner: _LoopThread) -> None:
        super().__init__(err.conflicts, err._transaction, err.seen_at)
        self._runner = runner

    def merge(self) -> Blocking:  # type: ignore[override]
        """See `ConflictError.merge`; the new transaction's methods block."""
        return Blocking(super().merge(), self._runner)


def open_peer(path: str | Path = ".") -> Blocking:
    """A blocking proxy of the application's peer of `path` (`mapapi.app.open_peer`:
    with the map tables' rules, as `mapctl` opens it)."""
    runner = _LoopThread()
    return Blocking(runner.call(app.open_peer, path), runner)


def wrap(peer: Peer) -> Blocking:
    """A blocking proxy of an existing peer (which must not be in use by a loop)."""
    return Blocking(peer, _LoopThread())
