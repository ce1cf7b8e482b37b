"""The peer daemon of a repository: `mapctl peer start` (DESIGN §9).

`serve()` opens the repository, puts its peer on the network, joins the
given members, serves the local control endpoint (`mapapi.service.control`) and
writes `.mapapi/peer.pid` (atomically, once everything serves), then runs
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
import sys
import time
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING
from urllib.parse import urlsplit

from mapapi.core.errors import MapError
from mapapi.service import known_peers
from mapapi.service.daemon_process import LOG_ENV, refuse_if_running
from mapapi.service.loop_lag import LoopLag
from mapapi.service.pacing import Pacing
from mapapi.service.peer_lock import PeerLock
from mapapi.service.repo import PeerRecord
from mapapi.store.wal import WalKeeper
from mapapi.swarm import faults

if TYPE_CHECKING:
    from mapapi.service.control import ControlServer
    from mapapi.service.ops import OperationsFactory
    from mapapi.service.peer import Peer
    from mapapi.service.repo import Repository

PeerFactory = Callable[["Repository"], "Peer"]
"""What opens a repository's peer (`mapapi.app.peer_of`: with the application's rules)."""

log = logging.getLogger(__name__)

_WILDCARD_HOSTS = frozenset({"0.0.0.0", "*"})


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
    """`seeds` with the first one to answer a ping moved to the front; none if
    none answers (a swarm restarting as a whole: the first peer up serves at
    once, and the others, which remember it, join it as they start).

    All are pinged at once: remembered members that since stopped, or restarted on
    other ports, would otherwise each cost a join's whole timeout in turn.
    """
    from mapapi.net.asking import first_answer
    from mapapi.net.codec import Ping, Pong

    assert peer.swarm is not None
    rpc = peer.swarm.rpc

    async def ping(seed: str) -> str:
        await rpc.request(seed, Ping(), timeout=SEED_PROBE_TIMEOUT, expect=Pong)
        return seed

    first = await first_answer([ping(seed) for seed in seeds])
    for seed in seeds:
        if seed != first:
            await rpc.forget(seed)  # no reconnecting socket to a member that moved
    return [] if first is None else [first, *(s for s in seeds if s != first)]


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

    Raises:
        UsageError: a peer already runs on the repository.
        NetworkError: `listen` cannot be bound, or no seed answered.
    """
    from mapapi.service.control import ControlServer

    faults.arm_from_env(os.environ)  # failure tests: see mapapi.swarm.faults
    stop = stop or asyncio.Event()
    lock = PeerLock.acquire(repo)
    lag = LoopLag()  # how late the loop runs: `peer status` (issue 14 §1)
    lag.start()
    pacing = Pacing()  # and what keeps it on time (issue 14 §1)
    pacing.start()
    try:
        peer = open_peer(repo)
        wal = WalKeeper(peer.store)  # its log checkpointed in a worker, never on the loop
        wal.start()
        control = ControlServer(operations(peer, on_shutdown=stop.set, loop_lag=lag))
        record: PeerRecord | None = None
        keeper: asyncio.Task[None] | None = None
        try:
            record = await _go_live(repo, control, listen, join, advertise)
            keeper = asyncio.get_running_loop().create_task(_keep_members(repo, peer))
            pacing.settle()
            if ready is not None:
                ready(record)
            await stop.wait()
            log.info("peer %s stopping", peer.id.short)
        finally:
            if keeper is not None:
                keeper.cancel()
                await asyncio.gather(keeper, return_exceptions=True)
            control.stopping = True  # answer "stopping" while the members hear Bye
            await wal.close()
            await peer.close()
            await control.close()
            if record is not None:
                repo.remove_peer_record(record.pid)
    finally:
        await pacing.close()
        await lag.close()
        lock.release()


async def _go_live(
    repo: Repository,
    control: ControlServer,
    listen: str,
    join: Sequence[str],
    advertise: str | None,
) -> PeerRecord:
    """Start the peer, join (through `join`, or else the members it knew when it
    last ran), serve the control endpoint, write the pid file."""
    peer = control.ops.peer
    bound = await peer.start(known_peers.preferred_listen(repo, listen))
    known_peers.remember_listen(repo, bound)
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
    """Remember the other members' addresses whenever they change (`known_peers`):
    those that said goodbye too, as they come back to the same chunks' groups."""
    known: set[str] | None = None
    while True:
        departed = peer.swarm.members.departed() if peer.swarm is not None else []
        members = [*(s.member for s in peer.members()), *departed]
        current = {m.address for m in members if m.address}
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
