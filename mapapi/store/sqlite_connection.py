"""The connections of one SQLite store file: one per thread, and its write transaction.

Several threads and several processes may open the same file. Each thread gets
its own connection; committers serialise on SQLite's write lock
(`BEGIN IMMEDIATE`), and nested write transactions join the outer one.
"""

from __future__ import annotations

import sqlite3
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

from mapapi.core.errors import LockTimeout
from mapapi.store.file_check import storage_error

BUSY_TIMEOUT_MS = 30_000

WAL_LIMIT_BYTES = 64 * 1024 * 1024
"""Size the write-ahead log file is cut back to once checkpointed (SQLite keeps it
at its largest otherwise: a mission imported once left 20 MB of it for good)."""


class WriteBusy(Exception):
    """Another connection holds SQLite's write lock, and the caller would not wait
    (`Connections.no_wait`): never leaves the process."""


CLOSE_WAIT = 60.0
"""Seconds `Connections.close` waits for worker threads still reading."""


class Connections:
    """Every thread's connection to the store file at `path`.

    Args:
        on_commit: called with the connection after each outermost write
            transaction commits (not after one that rolls back).
        on_rollback: called after one rolls back.
    """

    def __init__(
        self,
        path: Path,
        on_commit: Callable[[sqlite3.Connection], None] | None = None,
        on_rollback: Callable[[], None] | None = None,
    ) -> None:
        self.path = path
        self._on_commit = on_commit
        self._on_rollback = on_rollback
        self._local = threading.local()
        self._all: list[sqlite3.Connection] = []
        self._all_lock = threading.Lock()
        self._idle = threading.Condition(self._all_lock)  # no worker thread reads
        self._workers = 0

    def con(self) -> sqlite3.Connection:
        """This thread's connection (opened on first use)."""
        con: sqlite3.Connection | None = getattr(self._local, "con", None)
        if con is None:
            con = sqlite3.connect(
                self.path, isolation_level=None, check_same_thread=False, timeout=30
            )
            con.execute(f"PRAGMA busy_timeout={BUSY_TIMEOUT_MS}")
            con.execute("PRAGMA synchronous=NORMAL")
            con.execute("PRAGMA foreign_keys=ON")
            con.execute(f"PRAGMA journal_size_limit={WAL_LIMIT_BYTES}")
            self._local.con = con
            self._local.depth = 0
            self._local.no_wait = self._local.hurried = False
            with self._all_lock:
                self._all.append(con)
        return con

    @contextmanager
    def write(self, con: sqlite3.Connection) -> Iterator[None]:
        """One write transaction; nested uses join the outer one."""
        if self._local.depth:
            self._local.depth += 1
            try:
                yield
            finally:
                self._local.depth -= 1
            return
        self._begin(con)
        self._local.depth = 1
        try:
            yield
            con.execute("COMMIT")
        except BaseException as exc:
            if con.in_transaction:  # on a full disk SQLite may have rolled back already
                con.execute("ROLLBACK")
            if self._on_rollback is not None:
                self._on_rollback()
            if isinstance(exc, sqlite3.Error) and (honest := storage_error(self.path, exc)):
                raise honest from exc
            raise
        finally:
            self._local.depth = 0
        if self._on_commit is not None:
            self._on_commit(con)

    def _begin(self, con: sqlite3.Connection) -> None:
        """BEGIN IMMEDIATE: wait for the write lock, unless this thread asked not to."""
        hurry = self._local.no_wait
        if hurry:
            con.execute("PRAGMA busy_timeout=0")
        try:
            con.execute("BEGIN IMMEDIATE")
        except sqlite3.OperationalError as exc:
            if hurry and exc.sqlite_errorcode == sqlite3.SQLITE_BUSY:
                raise WriteBusy(str(self.path)) from None
            locked = LockTimeout(f"repository {self.path} stayed locked: {exc}")
            raise storage_error(self.path, exc) or locked from exc
        finally:
            if hurry:
                con.execute(f"PRAGMA busy_timeout={BUSY_TIMEOUT_MS}")

    @contextmanager
    def no_wait(self) -> Iterator[None]:
        """Within the block, this thread's outermost write transactions do not wait
        for SQLite's write lock: they raise `WriteBusy` while another connection
        holds it (the event loop's writes, which a worker's long one must not stall).
        Its connection no longer checkpoints the log either: the commit that
        crosses SQLite's threshold copies the whole log into the file, tens of ms
        after a big install; workers' commits and `checkpoint` do that instead."""
        con = self.con()
        if not self._local.hurried:
            con.execute("PRAGMA wal_autocheckpoint=0")
            self._local.hurried = True
        self._local.no_wait = True
        try:
            yield
        finally:
            self._local.no_wait = False

    def checkpoint(self) -> None:
        """Copy what the write-ahead log holds into the file, as far as no reader
        still needs it (PASSIVE: waits for no one), and cut the log back."""
        self.con().execute("PRAGMA wal_checkpoint(PASSIVE)")

    @contextmanager
    def worker(self) -> Iterator[None]:
        """Mark the calling worker thread as using the store until the block ends:
        `close` waits for it (closing a connection while another thread reads
        through it crashes SQLite's module)."""
        with self._idle:
            self._workers += 1
        try:
            yield
        finally:
            with self._idle:
                self._workers -= 1
                self._idle.notify_all()

    def close(self) -> None:
        """Close every connection opened by any thread, once no worker uses one
        (waiting at most `CLOSE_WAIT` seconds)."""
        with self._idle:
            self._idle.wait_for(lambda: self._workers == 0, timeout=CLOSE_WAIT)
            for con in self._all:
                con.close()
            self._all.clear()
        self._local = threading.local()
