"""A peer daemon seen from another process: start it detached, stop it (DESIGN §9).

`spawn_detached` starts `mapctl peer start` in a new session and returns once
it serves and answers on its control endpoint; `stop_daemon` asks it to shut
down over that endpoint, then signals it. Both go by the repository's pid file
and `PeerLock` (`mapapi.service.repo`); serving itself is `mapapi.service.daemon`.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import signal
import subprocess
import sys
import time
from collections.abc import Sequence
from typing import TYPE_CHECKING, BinaryIO

from mapapi.core.errors import MapError, PeerNotRunning, RequestTimeout, UsageError
from mapapi.service.repo import PeerRecord

if TYPE_CHECKING:
    from mapapi.service.repo import Repository

log = logging.getLogger(__name__)

START_TIMEOUT = 30.0
"""Seconds `--detach` waits for the daemon to serve."""
STOP_TIMEOUT = 20.0
"""Seconds `peer stop` waits for a graceful stop before it sends SIGTERM (then as long again)."""
_POLL = 0.02  # seconds between looks at another process's state
_DETACHED: list[subprocess.Popen[bytes]] = []  # daemons this process started

LOG_ENV = "MAPAPI_PEER_LOG"
"""Set by `spawn_detached` for its child: the log the child writes itself once it
serves. Until then its output goes through a pipe to the parent, which copies it
to the log and, when the child exits first, shows it: on a full disk the log
cannot be written and would leave "(see peer.log)" pointing at nothing."""


def refuse_if_running(repo: Repository) -> None:
    """Raise if a peer daemon runs on `repo`.

    Raises:
        UsageError: one does.
    """
    current = repo.running_peer()
    if current is not None:
        raise UsageError(
            f"a peer already runs on {repo.root} (pid {current.pid}, {current.address}); "
            "stop it with `mapctl peer stop` first"
        )


def daemon_command(
    repo: Repository,
    listen: str = "tcp://127.0.0.1:0",
    joins: Sequence[str] = (),
    advertise: str | None = None,
    verbose: bool = False,
) -> list[str]:
    """The command a detached daemon of `repo` runs: `mapctl peer start` in the
    foreground, under this Python (for `spawn_detached`)."""
    argv = [sys.executable, "-m", "mapctl", "-C", str(repo.root)]
    argv += ["-v"] if verbose else []
    argv += ["peer", "start", "--listen", listen]
    for address in joins:
        argv += ["--join", address]
    if advertise:
        argv += ["--advertise", advertise]
    return argv


def _log_tail(text: str) -> str:
    """The line of a child's output that says why it stopped."""
    lines = text.splitlines()
    errors = [line for line in lines if line.startswith("error:")]
    return (errors or [line for line in lines if line.strip()] or [""])[-1]


def spawn_detached(
    repo: Repository,
    argv: Sequence[str],
    timeout: float = START_TIMEOUT,
) -> PeerRecord:
    """Start `argv` (a command that serves `repo` in the foreground) as a daemon in
    a new session, its output appended to `.mapapi/peer.log`; return its record
    once it serves and answers on its control endpoint.

    Raises:
        UsageError: a peer already runs on the repository.
        PeerNotRunning: the daemon exited before it served.
        RequestTimeout: it did not serve within `timeout` seconds (it is killed).
    """
    refuse_if_running(repo)
    env = {**os.environ, "PYTHONUNBUFFERED": "1", LOG_ENV: str(repo.log_path)}
    deadline = time.monotonic() + timeout
    reader, writer = os.pipe()
    try:
        proc = subprocess.Popen(
            list(argv),
            stdin=subprocess.DEVNULL,
            stdout=writer,
            stderr=subprocess.STDOUT,
            cwd=repo.root,
            env=env,
            start_new_session=True,  # no terminal's SIGINT/SIGHUP reaches it
        )
    finally:
        os.close(writer)
    try:
        with os.fdopen(reader, "rb") as pipe:
            output, where = _relay(pipe, repo, deadline)
        record = _await_record(proc, repo, deadline, output, where)
        _ping(record, repo)
    except BaseException:
        _end(proc)
        raise
    _DETACHED.append(proc)  # it outlives this call on purpose: no "still running" warning
    return record


def _relay(pipe: BinaryIO, repo: Repository, deadline: float) -> tuple[str, str]:
    """Copy the child's output to its log until the child lets go of the pipe (it
    serves and writes the log itself, or it exits) or `deadline`; return the
    output and where to read it: the log, or why the log could not be written."""
    import select

    seen = bytearray()
    failed: OSError | None = None
    while (left := deadline - time.monotonic()) > 0:
        if not select.select([pipe], [], [], left)[0]:
            break
        chunk = os.read(pipe.fileno(), 65536)
        if not chunk:
            break  # the child serves (`_adopt_log`) or is gone
        seen += chunk
        del seen[: max(0, len(seen) - 65536)]  # the tail says why it stopped
        try:
            with open(repo.log_path, "ab") as out:
                out.write(chunk)
        except OSError as exc:
            failed = exc
    where = f"see {repo.log_path}"
    if failed is not None:
        where = f"{repo.log_path} could not be written: {failed.strerror or failed}"
    return seen.decode("utf-8", errors="replace"), where


def _await_record(
    proc: subprocess.Popen[bytes], repo: Repository, deadline: float, output: str, where: str
) -> PeerRecord:
    while True:
        code = proc.poll()
        if code is not None:
            raise PeerNotRunning(
                f"the peer exited (status {code}) before it served: {_log_tail(output)} ({where})"
            )
        record = repo.read_peer_record()
        if record is not None and record.pid == proc.pid:
            return record
        if time.monotonic() > deadline:
            raise RequestTimeout(f"the peer did not serve in time ({where})")
        time.sleep(_POLL)  # sync-ok: polling another process's state


def _ping(record: PeerRecord, repo: Repository) -> None:
    from mapapi.service.control import RemoteOperations

    async def ping() -> None:
        remote = RemoteOperations.of(repo, record)
        try:
            await remote.ping()
        finally:
            await remote.close()

    asyncio.run(ping())


def _end(proc: subprocess.Popen[bytes]) -> None:
    """Stop a child that failed to start: SIGTERM, then SIGKILL."""
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(timeout=5.0)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(timeout=5.0)


def stop_daemon(repo: Repository, timeout: float = STOP_TIMEOUT) -> PeerRecord | None:
    """Stop the daemon of `repo` gracefully; returns its record, or None if none ran
    (a stale pid file is removed).

    Asks through the control endpoint first, then, if the daemon is still there
    after `timeout` seconds, sends SIGTERM and waits as long again.

    Raises:
        RequestTimeout: the daemon did not stop.
    """
    record = repo.read_peer_record()
    if record is None or not repo.peer_locked():
        if record is not None:
            log.info("removing the stale pid file of pid %d", record.pid)
            repo.remove_peer_record(record.pid)
        return None
    try:
        _call(record, repo, "shutdown")
    except MapError as exc:  # not answering: fall back to the signal below
        log.warning("the peer did not take the shutdown call: %s", exc)
    if not _wait_unlocked(repo, timeout):
        with contextlib.suppress(ProcessLookupError):
            os.kill(record.pid, signal.SIGTERM)
        if not _wait_unlocked(repo, timeout):
            raise RequestTimeout(
                f"the peer (pid {record.pid}) did not stop within {2 * timeout:g} s; "
                f"`kill -9 {record.pid}` ends it (its pid file is then stale and ignored)"
            )
    _reap(record.pid, timeout)
    return record


def _reap(pid: int, timeout: float) -> None:
    """Wait for the exit of daemon `pid` if this process started it: it let go of
    its lock and is exiting; reaped, it is neither a zombie nor, at this process's
    exit, a "subprocess still running" warning."""
    for proc in [p for p in _DETACHED if p.pid == pid]:
        with contextlib.suppress(subprocess.TimeoutExpired):
            proc.wait(timeout)
            _DETACHED.remove(proc)


def _call(record: PeerRecord, repo: Repository, op: str) -> object:
    from mapapi.service.control import RemoteOperations

    async def call() -> object:
        remote = RemoteOperations.of(repo, record, timeout=5.0)
        try:
            return await remote.call(op, {})
        finally:
            await remote.close()

    return asyncio.run(call())


def _wait_unlocked(repo: Repository, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while repo.peer_locked():
        if time.monotonic() > deadline:
            return False
        time.sleep(_POLL)  # sync-ok: polling another process's state
    return True
