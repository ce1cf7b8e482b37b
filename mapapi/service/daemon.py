"""The peer daemon of a repository: `mapctl peer start` (DESIGN §9).

`serve()` opens the repository, puts its peer on the network, joins the
given members, serves the local control endpoint (`mapapi.service.control`) and
writes `.mapapi/service/peer.pid` (atomically, once everything serves), then runs
until it is told to stop: SIGTERM, SIGINT or SIGHUP (with `run()`), or the
`shutdown` operation that `mapctl peer stop` sends. Stopping is graceful: no
new control calls, Bye to every member, sockets closed, pid file removed.
While it runs it holds the repository's `PeerLock` (see `mapapi.service.repo`), which
tells a live daemon from a stale pid file.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, BinaryIO
from urllib.parse import urlsplit

from mapapi.core import faults
from mapapi.core.errors import MapError, PeerNotRunning, RequestTimeout, UsageError
from mapapi.service import known_peers
from mapapi.service.repo import PeerLock, PeerRecord

if TYPE_CHECKING:
    from mapapi.service.control import ControlServer
    from mapapi.service.ops import OperationsFactory
    from mapapi.service.peer import Peer
    from mapapi.service.repo import Repository

PeerFactory = Callable[["Repository"], "Peer"]
"""What opens a repository's peer (`mapapi.app.peer_of`: with the application's rules)."""

log = logging.getLogger(__name__)

START_TIMEOUT = 30.0
"""Seconds `--detach` waits for the daemon to serve."""
STOP_TIMEOUT = 20.0
"""Seconds `peer stop` waits for a graceful stop before it sends SIGTERM (then as long again)."""
_POLL = 0.02  # seconds between looks at another process's state
_WILDCARD_HOSTS = frozenset({"0.0.0.0", "*"})
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


# -- the advertised address --------------------------------------------------------------
def advertised_address(bound: str, seeds: Sequence[str] = ()) -> str:
    """The address others reach a peer at that listens on `bound`.

    A wildcard host (`tcp://0.0.0.0:7000`, `tcp://*:7000`) is no address another
    machine can connect to, so it is replaced by this machine's IPv4 address on
    the route to the first seed (or, with no seed, on the default route; the
    loopback address when there is none). Other addresses are returned as is.
    """
    parts = urlsplit(bound)
    if parts.scheme != "tcp" or parts.hostname not in _WILDCARD_HOSTS or parts.port is None:
        return bound
    target = ("192.0.2.1", 9)  # TEST-NET-1: only picks a route, nothing is sent
    for seed in seeds:
        seed_parts = urlsplit(seed)
        if seed_parts.hostname and seed_parts.hostname not in _WILDCARD_HOSTS:
            target = (seed_parts.hostname, seed_parts.port or 9)
            break
    host = "127.0.0.1"
    with contextlib.suppress(OSError), socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.connect(target)  # UDP connect sends nothing; it asks the routing table
        host = probe.getsockname()[0]
    return f"tcp://{host}:{parts.port}"


# -- serving ------------------------------------------------------------------------------
async def _join_all(peer: Peer, seeds: Sequence[str]) -> None:
    """Join through each seed; fail only if every one fails."""
    failures: list[MapError] = []
    for seed in seeds:
        try:
            await peer.join(seed)
        except MapError as exc:
            log.warning("joining through %s failed: %s", seed, exc)
            failures.append(exc)
    if seeds and len(failures) == len(seeds):
        raise failures[-1]


SEED_PROBE_TIMEOUT = 2.0
"""Seconds a restarted daemon waits for the members it remembers to answer a ping."""


async def _rejoin_any(peer: Peer, seeds: Sequence[str]) -> None:
    """Rejoin the swarm through a remembered member (one is enough: it tells this
    peer every other), the first to answer a ping first; if none does, the swarm
    may be gone, so the peer serves alone and its commits to shared chunks say
    why they fail."""
    for seed in await _first_to_answer(peer, seeds):
        try:
            await peer.join(seed)
            return
        except MapError as exc:
            log.warning("rejoining through %s failed: %s", seed, exc)
    log.warning("could not rejoin through any of the %d members it knew", len(seeds))


async def _first_to_answer(peer: Peer, seeds: Sequence[str]) -> list[str]:
    """`seeds` with the first one to answer a ping moved to the front.

    All are pinged at once: remembered members that since stopped, or restarted on
    other ports, would otherwise each cost a join's whole timeout in turn.
    """
    from mapapi.net.codec import Ping, Pong
    from mapapi.net.rpc import first_answer

    assert peer.swarm is not None
    rpc = peer.swarm.rpc

    async def ping(seed: str) -> str:
        await rpc.request(seed, Ping(), timeout=SEED_PROBE_TIMEOUT, expect=Pong)
        return seed

    first = await first_answer([ping(seed) for seed in seeds])
    for seed in seeds:
        if seed != first:
            await rpc.forget(seed)  # no reconnecting socket to a member that moved
    return list(seeds) if first is None else [first, *(s for s in seeds if s != first)]


async def serve(
    repo: Repository,
    listen: str = "tcp://127.0.0.1:0",
    join: Sequence[str] = (),
    *,
    open_peer: PeerFactory,
    operations: OperationsFactory,
    advertise: str | None = None,
    stop: asyncio.Event | None = None,
    ready: Callable[[PeerRecord], None] | None = None,
    lease: float = 5.0,
) -> None:
    """Run the peer of `repo` until `stop` is set (or a `shutdown` operation).

    Args:
        repo: the repository.
        listen: the swarm endpoint; port 0 picks a free port.
        join: addresses of members to join through.
        open_peer: opens the repository's peer (the application's, `mapapi.app`).
        operations: builds the operations the control endpoint serves over it.
        advertise: the address to tell other peers (default: the bound one,
            see `advertised_address`).
        stop: set it to stop gracefully.
        ready: called with the pid file's record once everything serves.
        lease: seconds a write lock lasts unless renewed.

    Raises:
        UsageError: a peer already runs on the repository.
        NetworkError: `listen` cannot be bound, or no seed answered.
    """
    from mapapi.service.control import ControlServer

    faults.arm_from_env(os.environ)  # failure tests: see mapapi.core.faults
    stop = stop or asyncio.Event()
    lock = PeerLock.acquire(repo)
    try:
        peer = open_peer(repo)
        control = ControlServer(operations(peer, on_shutdown=stop.set))
        record: PeerRecord | None = None
        keeper: asyncio.Task[None] | None = None
        try:
            record = await _go_live(repo, control, listen, join, advertise, lease)
            keeper = asyncio.get_running_loop().create_task(_keep_members(repo, peer))
            if ready is not None:
                ready(record)
            await stop.wait()
            log.info("peer %s stopping", peer.id.short)
        finally:
            if keeper is not None:
                keeper.cancel()
                await asyncio.gather(keeper, return_exceptions=True)
            control.stopping = True  # answer "stopping" while the members hear Bye
            await peer.close()
            await control.close()
            if record is not None:
                repo.remove_peer_record(record.pid)
    finally:
        lock.release()


async def _go_live(
    repo: Repository,
    control: ControlServer,
    listen: str,
    join: Sequence[str],
    advertise: str | None,
    lease: float,
) -> PeerRecord:
    """Start the peer, join (through `join`, or else the members it knew when it
    last ran), serve the control endpoint, write the pid file."""
    peer = control.ops.peer
    bound = await peer.start(listen, lease=lease)
    assert peer.swarm is not None
    recalled = [] if join else known_peers.recall(repo)
    wanted = advertise or advertised_address(bound, join or recalled)
    if wanted != bound:
        peer.swarm.advertise(wanted)  # a secure peer's gets its key (DESIGN §10)
    address = peer.address
    if join:
        await _join_all(peer, join)
    elif recalled:
        log.info("rejoining through the %d members it remembers", len(recalled))
        await _rejoin_any(peer, recalled)
    endpoint = await control.start(repo)
    record = PeerRecord(os.getpid(), peer.id, peer.name, address, address, endpoint, time.time())
    repo.write_peer_record(record)
    log.info("peer %s serves %s (control %s)", peer.id.short, address, endpoint)
    _adopt_log(os.environ.get(LOG_ENV))
    return record


def _adopt_log(path: str | None) -> None:
    """Point this process's stdout and stderr at its log `path` (a detached
    daemon, once it serves: see `LOG_ENV`); the parent reading the pipe they
    were sees its end and returns. If the log cannot be opened, output goes to
    /dev/null (the daemon runs on; the parent shows why)."""
    if not path:
        return
    try:
        fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    except OSError as exc:
        log.warning("cannot write %s (%s): the daemon's output is dropped", path, exc)
        fd = os.open(os.devnull, os.O_WRONLY)
    sys.stdout.flush()
    sys.stderr.flush()
    os.dup2(fd, 1)
    os.dup2(fd, 2)
    os.close(fd)


REMEMBER_PERIOD = 2.0
"""Seconds between checks of the member list the daemon keeps in `.mapapi/`."""


async def _keep_members(repo: Repository, peer: Peer) -> None:
    """Remember the other members' addresses whenever they change (`known_peers`)."""
    known: set[str] | None = None
    while True:
        current = {s.member.address for s in peer.members() if s.member.address}
        if current and current != known:
            try:
                known_peers.remember(repo, current)
                known = current
            except OSError as exc:
                log.warning("could not remember the swarm's members: %s", exc)
        await asyncio.sleep(REMEMBER_PERIOD)


def run(
    repo: Repository,
    listen: str = "tcp://127.0.0.1:0",
    join: Sequence[str] = (),
    *,
    open_peer: PeerFactory,
    operations: OperationsFactory,
    advertise: str | None = None,
    ready: Callable[[PeerRecord], None] | None = None,
) -> None:
    """`serve()` in its own event loop until SIGTERM, SIGINT, SIGHUP or `shutdown`.

    Raises:
        UsageError: a peer already runs on the repository.
    """
    refuse_if_running(repo)  # before touching signals: say it plainly

    async def main() -> None:
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        signals = (signal.SIGTERM, signal.SIGINT, signal.SIGHUP)
        for sig in signals:
            loop.add_signal_handler(sig, stop.set)
        try:
            await serve(
                repo,
                listen,
                join,
                open_peer=open_peer,
                operations=operations,
                advertise=advertise,
                stop=stop,
                ready=ready,
            )
        finally:
            for sig in signals:
                loop.remove_signal_handler(sig)

    asyncio.run(main())


# -- controlling a daemon from another process ------------------------------------
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
    a new session, its output appended to `.mapapi/service/peer.log`; return its record
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
