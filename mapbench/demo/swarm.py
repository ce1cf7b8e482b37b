"""`LocalSwarm`: peer daemons in the repositories of one folder, for `mapctl demo`.

Each peer is a real `mapctl peer start` process, started the way `peer start
--detach` starts one (`mapapi.service.daemon_process.spawn_detached`) and driven over its
control endpoint with the operations `mapctl` uses (`RemoteOperations`).

`stop()` does not rely on what this process remembers: it stops the daemon of
every repository of the swarm that has one running (gracefully, all at once,
then SIGKILL for any that does not stop), so a daemon whose start was cut
short by Ctrl-C is stopped too. Call it after the event loop has finished
(`asyncio.run` waits for the threads that start daemons before it returns).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import signal
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mapapi.service.control import RemoteOperations
from mapapi.service.daemon_process import daemon_command, spawn_detached, stop_daemon
from mapapi.service.repo import PeerRecord, Repository

log = logging.getLogger(__name__)

Json = Any

STOP_TIMEOUT = 10.0
"""Seconds a graceful stop may take before the daemon is killed."""


@dataclass
class SwarmPeer:
    """One running daemon of the swarm and the connection to its control endpoint."""

    name: str
    repo: Repository
    record: PeerRecord
    ops: RemoteOperations

    async def call(self, op: str, **args: Json) -> Json:
        """Run operation `op` (of `mapapi.service.ops.Operations`) in the daemon."""
        return await self.ops.call(op, args)


class LocalSwarm:
    """Repositories named `names` under `root`, each to run one peer daemon.

    Args:
        root: an empty folder (the repositories are made in it).
        names: the peers' names; the first is the one the others join through.
    """

    def __init__(self, root: Path, names: Sequence[str]) -> None:
        self.root = root
        self.repos = [Repository.init(root / name, name) for name in names]
        self.peers: list[SwarmPeer] = []

    async def start(self, started: Callable[[SwarmPeer], None] | None = None) -> list[SwarmPeer]:
        """Start every daemon, one after the other (each joins through the first,
        once the ring holds the previous ones); `started` hears of each.

        Raises:
            MapError: a daemon did not serve (see its `.mapapi/peer.log`).
        """
        for repo in self.repos:
            joins = (self.peers[0].record.join,) if self.peers else ()
            argv = daemon_command(repo, joins=joins)
            record = await asyncio.to_thread(spawn_detached, repo, argv)
            peer = SwarmPeer(repo.root.name, repo, record, RemoteOperations.of(repo, record))
            self.peers.append(peer)
            if started is not None:
                started(peer)
        return self.peers

    async def disconnect(self) -> None:
        """Close the connections to the daemons (they keep running)."""
        for peer in self.peers:
            await peer.ops.close()

    def stop(self) -> list[int]:
        """Stop every daemon that runs in a repository of the swarm; returns their
        pids. Graceful stops run in parallel; a daemon that does not stop within
        `STOP_TIMEOUT` seconds, or when this is interrupted, is killed."""
        running = [(repo, repo.running_peer()) for repo in self.repos]
        running_now = [(repo, record) for repo, record in running if record is not None]
        if not running_now:
            return []
        try:
            with ThreadPoolExecutor(len(running_now)) as pool:
                for repo, _ in running_now:
                    pool.submit(_stop_or_kill, repo)
        finally:
            for repo, record in running_now:
                if repo.peer_locked():  # still alive: interrupted, or it would not stop
                    _kill(record.pid)
        return [record.pid for _, record in running_now]


def _stop_or_kill(repo: Repository) -> None:
    record = repo.read_peer_record()
    try:
        stop_daemon(repo, timeout=STOP_TIMEOUT / 2)
    except Exception as exc:  # any failure: the kill below still ends it
        log.warning("the peer of %s did not stop gracefully (%s); killing it", repo.root, exc)
        if record is not None:
            _kill(record.pid)


def _kill(pid: int) -> None:
    with contextlib.suppress(ProcessLookupError):
        os.kill(pid, signal.SIGKILL)
