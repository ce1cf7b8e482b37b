"""What a Raft leader tracks per follower, and its queue of pending ReadIndex requests.

Pure (DESIGN §13). Model: etcd-io/raft `tracker/progress.go`, `tracker/inflights.go` and
`read_only.go`.
"""

from __future__ import annotations

import enum
from collections import deque
from dataclasses import dataclass, field


class ProgressState(enum.Enum):
    """How the leader replicates to one follower."""

    PROBE = 1  # one append per heartbeat until the follower's log matches
    REPLICATE = 2  # optimistic pipelining: up to `max_inflight` appends in flight
    SNAPSHOT = 3  # a snapshot is on its way; send nothing else meanwhile


@dataclass
class Progress:
    """The leader's view of one follower's log (paper Fig. 2: nextIndex, matchIndex)."""

    match: int = 0
    next: int = 1
    state: ProgressState = ProgressState.PROBE
    probe_sent: bool = False
    pending_snapshot: int = 0
    snapshot_ticks: int = 0
    recent_active: bool = False
    inflights: deque[int] = field(default_factory=deque)

    def become_probe(self) -> None:
        """Probe from just after the last known match (or after the snapshot just sent)."""
        if self.state is ProgressState.SNAPSHOT:
            self.next = max(self.match, self.pending_snapshot) + 1
        else:
            self.next = self.match + 1
        self._reset(ProgressState.PROBE)

    def become_replicate(self) -> None:
        """The logs match up to `match`: pipeline from there."""
        self.next = self.match + 1
        self._reset(ProgressState.REPLICATE)

    def become_snapshot(self, index: int) -> None:
        """A snapshot up to `index` was sent."""
        self._reset(ProgressState.SNAPSHOT)
        self.pending_snapshot = index

    def _reset(self, state: ProgressState) -> None:
        self.state = state
        self.probe_sent = False
        self.pending_snapshot = 0
        self.snapshot_ticks = 0
        self.inflights.clear()

    def maybe_update(self, index: int) -> bool:
        """Record an acknowledgement of `index`; whether it raised `match`."""
        self.probe_sent = False
        if index <= self.match:
            return False
        self.match = index
        self.next = max(self.next, index + 1)
        return True

    def sent(self, last: int, count: int) -> None:
        """An append of `count` entries ending at `last` was sent."""
        if self.state is ProgressState.REPLICATE:
            if not count:
                return
            self.next = last + 1
            self.inflights.append(last)
        else:
            self.probe_sent = True

    def free_to(self, index: int) -> None:
        """Appends ending at or below `index` are no longer in flight."""
        while self.inflights and self.inflights[0] <= index:
            self.inflights.popleft()

    def maybe_decr_to(self, rejected: int, match_hint: int) -> bool:
        """Step `next` back after a rejection of the append after `rejected`.

        Returns False for a stale rejection (of an append sent before a later one).
        """
        if self.state is ProgressState.REPLICATE:
            if rejected <= self.match:
                return False
            self.next = self.match + 1
            return True
        if self.next - 1 != rejected:
            return False
        self.next = max(min(rejected, match_hint + 1), self.match + 1)
        self.probe_sent = False
        return True

    def is_paused(self, max_inflight: int) -> bool:
        """Whether the leader should send nothing new to this follower for now."""
        if self.state is ProgressState.PROBE:
            return self.probe_sent
        if self.state is ProgressState.REPLICATE:
            return len(self.inflights) >= max_inflight
        return True


@dataclass
class ReadRequest:
    """A ReadIndex request: the commit index when it arrived, who asked, who confirmed."""

    index: int
    context: bytes
    requester: int
    acks: set[int] = field(default_factory=set)


class ReadOnly:
    """ReadIndex requests waiting for a quorum of heartbeat acks (thesis §6.4, step 3)."""

    def __init__(self) -> None:
        self._pending: dict[bytes, ReadRequest] = {}

    def add(self, request: ReadRequest) -> None:
        """Queue a request; its context must be unique among the pending ones."""
        self._pending.setdefault(request.context, request)

    def ack(self, context: bytes, node: int) -> set[int] | None:
        """Record that `node` still follows this leader; the acks so far, or None."""
        request = self._pending.get(context)
        if request is None:
            return None
        request.acks.add(node)
        return request.acks

    def release(self, context: bytes) -> list[ReadRequest]:
        """Remove and return every request up to and including `context`.

        A quorum that confirmed a later request confirmed the earlier ones too.
        """
        if context not in self._pending:
            return []
        released: list[ReadRequest] = []
        for key in list(self._pending):
            released.append(self._pending.pop(key))
            if key == context:
                break
        return released

    def last_context(self) -> bytes:
        """The newest pending request's context (sent with each heartbeat), or b""."""
        return next(reversed(self._pending), b"")
