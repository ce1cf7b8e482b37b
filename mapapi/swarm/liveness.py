"""Heartbeats: watch the peers this one shares chunks with (issue 7 §1).

`Liveness` drives the pure `FailureDetector`. Every message from a peer counts
as a heartbeat (the RPC layer reports each one through `heard`); every
`interval` the peers that share a chunk with this one and were quiet that long
get a `Ping`, and the detector re-evaluates them all. When a peer is declared
dead its pending requests fail at once. What follows from a verdict is asked of
it by others: the leaders of a dead member's chunks remove it after a while
(`is_dead`, `swarm/group_members.py`), and a proposal that fails names the
voters that do not answer (`answers`, `swarm/log_commit.py`).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from dataclasses import dataclass

from mapapi.core.errors import MapError
from mapapi.core.ids import PeerId
from mapapi.net.codec import Ping
from mapapi.net.rpc import Rpc
from mapapi.store.base import ReplicaStore
from mapapi.swarm.failure import (
    DEAD_AFTER,
    REMOVE_AFTER,
    SUSPECT_AFTER,
    FailureDetector,
    Health,
    Transition,
)
from mapapi.swarm.membership import Members

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class LivenessOptions:
    """Timing of failure detection (seconds).

    Attributes:
        interval: how often quiet peers are pinged and health re-evaluated.
        suspect_after: silence before a peer is suspected.
        dead_after: silence before it is declared dead: requests to it fail at once.
        remove_after: how long it stays dead before the leader of each chunk's group
            it is a member of removes it (a membership change in the chunk's log,
            `swarm/group_members.py`); a learner is promoted in its place.
    """

    interval: float = 0.5
    suspect_after: float = SUSPECT_AFTER
    dead_after: float = DEAD_AFTER
    remove_after: float = REMOVE_AFTER


class Liveness:
    """Heartbeats and failure detection for one peer (see the module docstring).

    Args:
        rpc: the peer's endpoint (pings leave through it; `rpc.down` is kept here).
        members: who is who, and where.
        store: the chunks' holder sets (the co-holders are the peers watched).
        options: timing.
    """

    def __init__(
        self,
        rpc: Rpc,
        members: Members,
        store: ReplicaStore,
        options: LivenessOptions | None = None,
    ) -> None:
        self.rpc = rpc
        self.members = members
        self.store = store
        self.options = options or LivenessOptions()
        self.detector = FailureDetector(
            self.options.suspect_after,
            self.options.dead_after,
            pause_after=2 * self.options.interval,
        )
        self._task: asyncio.Task[None] | None = None
        self._pings: dict[PeerId, asyncio.Task[None]] = {}

    def start(self) -> None:
        """Start the heartbeat task."""
        self._task = asyncio.get_running_loop().create_task(self._run(), name="liveness")

    def heard(self, peer: PeerId) -> None:
        """A message from `peer` arrived (called by the RPC layer for every one)."""
        if self.rpc.down:
            member = self.members.get(peer)
            if member is not None:
                self.rpc.down.pop(member.address, None)
        change = self.detector.heard(peer, time.monotonic())
        if change is not None:
            self._report(change)

    def mark_down(self, peer: PeerId) -> None:
        """Treat `peer` as down until it is heard of again: requests to it fail at
        once, those pending now included (it was declared dead)."""
        member = self.members.get(peer)
        if member is not None and member.address:
            who = f"peer {self.members.label(peer)}"
            self.rpc.down[member.address] = who
            self.rpc.fail_pending(member.address, f"{who} is down")

    def is_dead(self, peer: PeerId) -> bool:
        """Whether `peer` is declared dead (silent for `dead_after` seconds)."""
        return self.detector.health(peer) is Health.DEAD

    def answers(self, peer: PeerId) -> bool:
        """Whether `peer` was heard of within `suspect_after` seconds (an unwatched
        peer counts as answering: nothing says otherwise)."""
        return self.detector.silent_for(peer, time.monotonic()) < self.options.suspect_after

    def co_holders(self) -> set[PeerId]:
        """The peers that share at least one chunk with this one."""
        me = self.members.me.id
        return {
            p for holders in self.store.holdings().values() if me in holders for p in holders
        } - {me}

    def tick(self) -> None:
        """One round: watch the co-holders, re-evaluate them, ping the quiet ones."""
        now = time.monotonic()
        watched = self.co_holders()
        for peer in set(self.detector.watched()) - watched:
            self.detector.unwatch(peer)
        for peer in watched:
            self.detector.watch(peer, now)
        for change in self.detector.tick(now):
            self._report(change)
        for peer in watched:
            quiet = self.detector.silent_for(peer, now) >= self.options.interval
            if quiet and peer not in self._pings:
                self._ping(peer)

    def _ping(self, peer: PeerId) -> None:
        """Ping `peer` in the background (a dead one must not stall the round)."""
        member = self.members.get(peer)
        if member is None or not member.address:
            return  # no address to reach it at: its silence counts
        task = asyncio.get_running_loop().create_task(self._send_ping(member.address))
        self._pings[peer] = task
        task.add_done_callback(lambda _: self._pings.pop(peer, None))

    async def _send_ping(self, address: str) -> None:
        # The reply (like any other message) reaches `heard` through the RPC layer.
        with contextlib.suppress(MapError):
            await self.rpc.request(address, Ping(), timeout=self.options.dead_after, probe=True)

    def _report(self, change: Transition) -> None:
        log.log(
            logging.WARNING if change.after is not Health.ALIVE else logging.INFO,
            "peer %s is %s (was %s)",
            change.peer.short,
            change.after.value,
            change.before.value,
        )
        if change.after is Health.DEAD:
            self.mark_down(change.peer)

    async def _run(self) -> None:
        while True:
            try:
                self.tick()
            except MapError as exc:  # the store failed: try next round
                log.warning("liveness round failed: %s", exc)
            await asyncio.sleep(self.options.interval)

    async def close(self) -> None:
        """Stop the heartbeat task."""
        tasks = [t for t in (self._task, *self._pings.values()) if t is not None]
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        self._task = None
