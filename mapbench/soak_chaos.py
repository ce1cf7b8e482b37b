"""The chaos of `mapctl bench soak` (`mapbench/soak.py`): what happens to its peer
daemons while their clients commit.

Every few seconds one of:

- **a crash**: SIGKILL, no goodbye;
- **a stop**: `peer stop`, which says goodbye (the peer stays a member of its
  chunks' groups);
- **a pause**: SIGSTOP for one to four seconds, then SIGCONT, as a robot whose
  process the OS stalled (the others suspect it, and elect another leader if it
  led; when it runs again it must not depose anyone, and must catch up);
- **a start** of the peer that is down, without `--join` (it rejoins through the
  members it remembered), half the time on a new port: it must tell the others
  where it serves now.

At most one peer is down or paused at a time, so the others are always a quorum.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import random
import signal
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from mapapi.core.errors import MapError
from mapapi.service.control import RemoteOperations
from mapapi.service.daemon_process import daemon_command, spawn_detached, stop_daemon
from mapapi.service.repo import Repository

log = logging.getLogger(__name__)

CHAOS_PERIOD = (2.0, 5.0)
"""Seconds between two chaos actions (uniform)."""
PAUSE = (1.0, 4.0)
"""Seconds a paused peer stays stopped (uniform): past the failure detector's
suspicion (1.5 s) and an election, short of its removal from the groups."""


@dataclass
class Tally:
    """What the clients and the chaos did."""

    increments: int = 0  # acknowledged
    transfers: int = 0  # acknowledged
    unknown_increments: int = 0  # the peer died mid-commit, or the commit was uncertain
    unknown_transfers: int = 0
    conflicts: int = 0
    retries: int = 0
    crashes: int = 0
    stops: int = 0
    pauses: int = 0
    restarts: int = 0
    moves: int = 0  # restarts on a new port
    restart_s: list[float] = field(default_factory=list)  # each restart until it served


@dataclass
class Node:
    """One peer of the soak: its repository and, while it runs, its client."""

    repo: Repository
    ops: RemoteOperations | None = None
    up: asyncio.Event = field(default_factory=asyncio.Event)

    async def call(self, op: str, **args: Any) -> Any:
        """Run one control operation on the peer; its JSON result."""
        assert self.ops is not None
        return await self.ops.call(op, args)

    async def disconnect(self) -> None:
        """Close the client's connection to the peer, if any."""
        if self.ops is not None:
            await self.ops.close()
            self.ops = None


class Chaos:
    """Crashes, stops, pauses and restarts among `nodes` (see the module docstring).

    Args:
        nodes: the soak's peers.
        rng: chooses what happens, to whom, and when.
        tally: counts what happened.
        report: called after each action (progress).
    """

    def __init__(
        self, nodes: list[Node], rng: random.Random, tally: Tally, report: Callable[[], None]
    ) -> None:
        self.nodes, self.rng, self.tally, self.report = nodes, rng, tally, report
        self.errors: list[str] = []  # actions that failed (the node starts again later)

    async def run(self, stop: asyncio.Event) -> None:
        """Act every few seconds until `stop` is set."""
        while True:
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(stop.wait(), self.rng.uniform(*CHAOS_PERIOD))
                return
            down = [i for i, n in enumerate(self.nodes) if not n.up.is_set()]
            choice = self.rng.random()
            pick = self.rng.randrange(len(self.nodes))
            try:
                if down:
                    await self.start(down[0], move=choice < 0.5)
                elif choice < 0.5:
                    await self._crash(pick)
                elif choice < 0.7:
                    await self._leave(pick)
                else:
                    await self._pause(pick, stop)
            except MapError as exc:  # reported; the node stays down and starts again later
                self.errors.append(f"chaos: {type(exc).__name__}: {exc}")
                log.warning("soak chaos: %s", exc)
            self.report()

    async def _crash(self, index: int) -> None:
        node = self.nodes[index]
        record = node.repo.running_peer()
        node.up.clear()
        if record is not None:
            os.kill(record.pid, signal.SIGKILL)  # no goodbye, as a crash
            self.tally.crashes += 1
            log.info("soak: killed %s (pid %d)", node.repo.root.name, record.pid)
        # The client keeps its connection: a call in flight must end in DaemonDied
        # (its outcome unknown), not in a closed connection that hides the commit.

    async def _leave(self, index: int) -> None:
        node = self.nodes[index]
        node.up.clear()  # the client finishes the operation it is in, then waits
        self.tally.stops += 1
        try:
            await asyncio.to_thread(stop_daemon, node.repo)
        except MapError:
            record = node.repo.running_peer()
            if record is not None:  # it would not stop: end it, as a crash
                os.kill(record.pid, signal.SIGKILL)
            raise
        log.info("soak: stopped %s", node.repo.root.name)

    async def _pause(self, index: int, stop: asyncio.Event) -> None:
        node = self.nodes[index]
        record = node.repo.running_peer()
        if record is None:
            return
        node.up.clear()  # its client waits (a call in flight completes once it runs again)
        os.kill(record.pid, signal.SIGSTOP)
        self.tally.pauses += 1
        log.info("soak: paused %s (pid %d)", node.repo.root.name, record.pid)
        try:
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(stop.wait(), self.rng.uniform(*PAUSE))
        finally:
            with contextlib.suppress(ProcessLookupError):
                os.kill(record.pid, signal.SIGCONT)
            node.up.set()

    async def start(self, index: int, move: bool = False) -> None:
        """Start the node's peer again without `--join`; with `move`, on a new port."""
        node = self.nodes[index]
        await node.disconnect()
        listen = f"tcp://127.0.0.1:{_free_port()}" if move else "tcp://127.0.0.1:0"
        argv = daemon_command(node.repo, listen)  # :0 takes its last port again if free
        began = time.monotonic()
        record = await asyncio.to_thread(spawn_detached, node.repo, argv)  # kills one that hangs
        self.tally.restart_s.append(time.monotonic() - began)
        node.ops = RemoteOperations.of(node.repo, record, alive=node.repo.peer_locked)
        node.up.set()
        self.tally.restarts += 1
        self.tally.moves += move
        log.info("soak: started %s again%s", node.repo.root.name, " elsewhere" if move else "")


def _free_port() -> int:
    """A port of 127.0.0.1 free now (the daemon binds it right after)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])
