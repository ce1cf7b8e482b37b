"""The writer's side of a commit through a chunk's Raft log (DESIGN §13).

The writer turns its transaction into a `Proposal` for the chunk and hands it to
the chunk's leader: itself, or the leader its group names, over the swarm port
(`RaftPropose`). The leader appends it, and once the entry applies there (every
holder decides it alike, `swarm/apply.py`) answers with the commit, or with the
conflicts as a `ConflictError`, or a rule's refusal as a `UsageError`. The
writer's transaction then knows its commit, or can be merged and tried again.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from mapapi.core import codec
from mapapi.core.clock import LamportClock
from mapapi.core.errors import ConflictError, UsageError
from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, PeerId
from mapapi.core.proposal import Proposal
from mapapi.core.transaction import Transaction
from mapapi.net.messages import RaftPropose, RaftProposed
from mapapi.net.rpc import Request, Rpc
from mapapi.swarm.apply import Outcome
from mapapi.swarm.groups import PROPOSE_TIMEOUT, NotChunkLeader, RaftGroups


@dataclass(frozen=True, slots=True)
class Committed:
    """A commit through the log: its record (None if it wrote nothing) and revisions."""

    record: CommitRecord | None
    revisions: tuple[Revision, ...]


class LogCommits:
    """Commits of this peer's transactions through the chunks' logs.

    Args:
        groups: this peer's Raft groups.
        rpc: the swarm's Rpc; serves `RaftPropose` for writers elsewhere.
        address: where a peer is reached now (the member list).
        clock: this peer's Lamport clock (a proposal's time; merged with the commit's).
    """

    def __init__(
        self,
        groups: RaftGroups,
        rpc: Rpc,
        address: Callable[[PeerId], str],
        clock: LamportClock,
    ) -> None:
        self.groups = groups
        self.rpc = rpc
        self._address = address
        self.clock = clock
        rpc.register(RaftPropose, self.rpc_raft_propose)

    async def commit(self, chunk: ChunkId, tx: Transaction, message: str) -> Committed:
        """Commit `tx`'s writes to `chunk` through the chunk's log.

        Raises:
            ConflictError: someone changed an item of `tx` since its begin time
                (mergeable here: it carries `tx`).
            UsageError: a commit rule refused the changes.
            NotChunkLeader: no leader is known yet (an election; retry).
            RequestTimeout: no majority of the chunk's voters took the entry.
            NetworkError: the leader could not be reached.
        """
        proposal = Proposal.of(tx, chunk, message, self.clock.tick())
        try:
            done = await self._propose(chunk, codec.encode_proposal(proposal))
        except ConflictError as exc:  # received from a leader elsewhere: make it mergeable here
            raise ConflictError(exc.conflicts, tx, exc.seen_at) from None
        if done.record is not None:
            self.clock.advance_to(done.record.time)
        tx.committed(list(done.revisions))
        return done

    async def _propose(self, chunk: ChunkId, data: bytes) -> Committed:
        if self.groups.is_leader(chunk):
            return self._result(chunk, (await self.groups.propose(chunk, data)).result)
        leader = self.groups.leader(chunk)
        if leader is None:
            raise NotChunkLeader(chunk, None)
        answer = await self.call_raft_propose(leader, chunk, data)
        return Committed(answer.record, answer.revisions)

    async def call_raft_propose(self, leader: PeerId, chunk: ChunkId, data: bytes) -> RaftProposed:
        """Ask `leader` to propose `data` to `chunk`'s log and wait for it to apply."""
        body = RaftPropose(chunk, data)
        return await self.rpc.request(
            self._address(leader), body, timeout=PROPOSE_TIMEOUT + 1.0, expect=RaftProposed
        )

    async def rpc_raft_propose(self, req: Request) -> RaftProposed:
        """Propose a writer's transaction as this chunk's leader; answer once applied.

        Raises:
            NotChunkLeader: this peer does not lead the chunk (the writer asks again).
            ConflictError, UsageError: how the holders decided it.
        """
        body: RaftPropose = req.body
        if not self.groups.is_leader(body.chunk):
            raise NotChunkLeader(body.chunk, self.groups.leader(body.chunk))
        codec.decode_proposal(body.proposal)  # refuse what would not apply (CorruptRepoError)
        done = self._result(
            body.chunk, (await self.groups.propose(body.chunk, body.proposal)).result
        )
        return RaftProposed(done.record, done.revisions)

    def _result(self, chunk: ChunkId, outcome: object) -> Committed:
        """The commit an applied proposal made, or the error it met."""
        assert isinstance(outcome, Outcome)  # the groups apply with `apply.applier`
        if outcome.conflicts:
            raise ConflictError(list(outcome.conflicts), None, self.groups.store.raft_time(chunk))
        if outcome.refusal:
            raise UsageError(outcome.refusal)
        return Committed(outcome.record, outcome.revisions)
