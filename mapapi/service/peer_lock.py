"""The exclusive lock a peer daemon holds on its repository (`.mapapi/peer.lock`)
for its whole life: the lock, not the pid file, tells whether a daemon runs."""

from __future__ import annotations

import fcntl
import os
import time
from typing import TYPE_CHECKING

from mapapi.core.errors import UsageError

if TYPE_CHECKING:
    from mapapi.service.repo import Repository


class PeerLock:
    """The exclusive lock a peer daemon holds on its repository for its lifetime."""

    def __init__(self, fd: int) -> None:
        self._fd: int | None = fd

    @classmethod
    def acquire(cls, repo: Repository, timeout: float = 2.0) -> PeerLock:
        """Lock `repo` for this process.

        Raises:
            UsageError: another daemon runs on the repository.
        """
        fd = os.open(repo.lock_path, os.O_RDWR | os.O_CREAT, 0o644)
        deadline = time.monotonic() + timeout
        while True:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                return cls(fd)
            except BlockingIOError:
                # A `peer_locked()` probe holds a shared lock for microseconds; a
                # daemon holds it for good.
                if time.monotonic() > deadline:
                    os.close(fd)
                    record = repo.read_peer_record()
                    who = f" (pid {record.pid}, {record.address})" if record else ""
                    raise UsageError(
                        f"a peer already runs on {repo.root}{who}; "
                        "stop it with `mapctl peer stop` first"
                    ) from None
                time.sleep(0.01)  # sync-ok: waiting out another process's probe

    def release(self) -> None:
        """Unlock (idempotent)."""
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None
