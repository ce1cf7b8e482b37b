"""The chunk lock state machine: never two writers, no request lost, leases expire."""

from __future__ import annotations

import pytest
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, invariant, precondition, rule

from mapapi.core.errors import LockNotHeld
from mapapi.core.ids import PeerId
from mapapi.swarm.lock import ChunkLock, Grant

WRITERS = [PeerId(f"{i:032x}") for i in range(1, 5)]


class LockMachine(RuleBasedStateMachine):
    """Random requests, releases, reads and clock jumps against one ChunkLock."""

    def __init__(self) -> None:
        super().__init__()
        self.lock = ChunkLock(lease=10.0)
        self.now = 0.0
        self.waiting: set[PeerId] = set()  # asked, not yet granted, not cancelled
        self.granted: list[Grant] = []  # every grant ever made, in order

    def _record(self, grant: Grant | None) -> None:
        if grant is not None and (not self.granted or self.granted[-1] != grant):
            self.granted.append(grant)
            self.waiting.discard(grant.writer)

    @rule(writer=st.sampled_from(WRITERS))
    def request(self, writer: PeerId) -> None:
        before = self.lock.grant
        grant = self.lock.request(writer, self.now)
        if grant is None:
            self.waiting.add(writer)
        elif before is not None and before.writer == writer:
            assert grant.token == before.token  # a retried request renews the same lease
            assert grant.expires == self.now + self.lock.lease
            self.granted[-1] = grant
        self._record(grant)
        self._record(self.lock.grant)

    @precondition(lambda self: self.lock.grant is not None)
    @rule()
    def release(self) -> None:
        grant = self.lock.grant
        assert grant is not None
        self._record(self.lock.release(grant.writer, grant.token, self.now))

    @precondition(lambda self: bool(self.granted))
    @rule(data=st.data())
    def stale_token_refused(self, data: st.DataObject) -> None:
        old = data.draw(st.sampled_from(self.granted))
        current = self.lock.grant
        if current is not None and current.token == old.token and current.writer == old.writer:
            return
        with pytest.raises(LockNotHeld):
            self.lock.release(old.writer, old.token, self.now)

    @rule(seconds=st.floats(min_value=0.0, max_value=15.0))
    def time_passes(self, seconds: float) -> None:
        self.now += seconds
        self._record(self.lock.expire(self.now))

    @rule()
    def local_read(self) -> None:
        if self.lock.acquire_read(self.now):
            assert self.lock.grant is None
            self._record(self.lock.release_read(self.now))

    @rule(writer=st.sampled_from(WRITERS))
    def cancel(self, writer: PeerId) -> None:
        self.lock.cancel(writer)
        self.waiting.discard(writer)

    @invariant()
    def one_writer_and_increasing_tokens(self) -> None:
        tokens = [g.token for g in self.granted]
        assert tokens == sorted(set(tokens)), "fencing tokens must strictly increase"
        grant = self.lock.grant
        assert grant is None or grant == self.granted[-1]

    @invariant()
    def no_request_lost(self) -> None:
        queued = set(self.lock.queue)
        assert self.waiting == queued, "every waiting writer is queued exactly once"
        assert len(self.lock.queue) == len(queued)
        if self.lock.grant is None and not self.lock.readers:
            assert not self.lock.queue, "a free lock must not leave writers waiting"


TestLockMachine = LockMachine.TestCase


class TestLease:
    def test_expired_lease_passes_the_lock_to_the_next_writer(self) -> None:
        lock = ChunkLock(lease=1.0)
        a, b = WRITERS[0], WRITERS[1]
        first = lock.request(a, now=0.0)
        assert first is not None
        assert lock.request(b, now=0.5) is None
        nxt = lock.expire(now=1.0)
        assert nxt is not None
        assert nxt.writer == b
        assert nxt.token > first.token
        with pytest.raises(LockNotHeld):
            lock.release(a, first.token, now=1.1)

    def test_renewed_lease_does_not_expire(self) -> None:
        lock = ChunkLock(lease=1.0)
        grant = lock.request(WRITERS[0], now=0.0)
        assert grant is not None
        lock.renew(grant.writer, grant.token, now=0.9)
        assert lock.expire(now=1.5) is None
        assert lock.grant is not None
        assert lock.grant.writer == WRITERS[0]

    def test_writer_waits_for_local_readers(self) -> None:
        lock = ChunkLock()
        assert lock.acquire_read(now=0.0)
        assert lock.request(WRITERS[0], now=0.0) is None
        grant = lock.release_read(now=0.1)
        assert grant is not None
        assert grant.writer == WRITERS[0]
        assert not lock.acquire_read(now=0.2)
