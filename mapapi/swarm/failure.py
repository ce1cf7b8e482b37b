"""Failure detection: which peers are alive, suspected or dead (pure state machine).

Every message from a peer counts as a sign of life (`heard`); the liveness
driver (`mapapi.swarm.liveness`) pings the peers it must watch when they are quiet.
A peer silent for `suspect_after` seconds becomes SUSPECT, for `dead_after`
seconds DEAD; any message makes it ALIVE again. Suspicion alone changes
nothing but the error a request to it gets; a peer dead for a while is removed
from its chunks' groups by their leaders, through the logs
(`mapapi.swarm.group_members`), so a wrong verdict (a slow peer, a partition)
costs a membership change, never a second history.
Time is a parameter (`now`, monotonic seconds).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from mapapi.core.ids import PeerId

SUSPECT_AFTER = 1.5
DEAD_AFTER = 3.0
REMOVE_AFTER = 30.0
"""Seconds a peer stays declared dead before the leaders of its chunks' groups remove it."""


class Health(enum.Enum):
    """What this peer believes of another one."""

    ALIVE = "alive"
    SUSPECT = "suspect"
    DEAD = "dead"


@dataclass(frozen=True, slots=True)
class Transition:
    """A peer's health changed."""

    peer: PeerId
    before: Health
    after: Health


class FailureDetector:
    """Health of the watched peers from the time each was last heard of.

    Args:
        suspect_after: seconds of silence before a peer is suspected.
        dead_after: seconds of silence before it is declared dead.
        pause_after: a gap between two ticks longer than this means this
            process itself stood still (a stalled event loop, a suspended
            process), when nothing could be heard: the gap does not count as
            anyone's silence. None counts every gap.

    Raises:
        ValueError: the thresholds are not 0 < suspect_after <= dead_after.
    """

    def __init__(
        self,
        suspect_after: float = SUSPECT_AFTER,
        dead_after: float = DEAD_AFTER,
        pause_after: float | None = None,
    ) -> None:
        if not 0 < suspect_after <= dead_after:
            raise ValueError(
                f"need 0 < suspect_after <= dead_after, got {suspect_after}, {dead_after}"
            )
        self.suspect_after = suspect_after
        self.dead_after = dead_after
        self.pause_after = pause_after
        self._last: dict[PeerId, float] = {}
        self._health: dict[PeerId, Health] = {}
        self._ticked: float | None = None

    def watch(self, peer: PeerId, now: float) -> None:
        """Start watching `peer` (as if just heard of); no-op if watched already."""
        if peer not in self._last:
            self._last[peer] = now
            self._health[peer] = Health.ALIVE

    def unwatch(self, peer: PeerId) -> None:
        """Stop watching `peer` (it left, or shares nothing with us any more)."""
        self._last.pop(peer, None)
        self._health.pop(peer, None)

    def watched(self) -> list[PeerId]:
        """The watched peers, in id order."""
        return sorted(self._last)

    def heard(self, peer: PeerId, now: float) -> Transition | None:
        """A message from `peer` arrived; returns its transition back to ALIVE, if any."""
        if peer not in self._last:
            return None
        self._last[peer] = max(self._last[peer], now)
        return self._set(peer, Health.ALIVE)

    def health(self, peer: PeerId) -> Health:
        """What we believe of `peer` (an unwatched peer counts as alive)."""
        return self._health.get(peer, Health.ALIVE)

    def silent_for(self, peer: PeerId, now: float) -> float:
        """Seconds since `peer` was last heard of (0 for an unwatched peer)."""
        last = self._last.get(peer)
        return 0.0 if last is None else max(0.0, now - last)

    def tick(self, now: float) -> list[Transition]:
        """Re-evaluate every watched peer at `now`; returns the transitions, in id order."""
        gap = 0.0 if self._ticked is None else now - self._ticked
        self._ticked = now
        if self.pause_after is not None and gap > self.pause_after:
            for peer in self._last:  # we were not listening: nobody was silent
                self._last[peer] += gap
        changes = []
        for peer in self.watched():
            silence = now - self._last[peer]
            if silence >= self.dead_after:
                target = Health.DEAD
            elif silence >= self.suspect_after:
                target = Health.SUSPECT
            else:
                target = Health.ALIVE
            change = self._set(peer, target)
            if change is not None:
                changes.append(change)
        return changes

    def _set(self, peer: PeerId, target: Health) -> Transition | None:
        before = self._health[peer]
        if before is target:
            return None
        self._health[peer] = target
        return Transition(peer, before, target)
