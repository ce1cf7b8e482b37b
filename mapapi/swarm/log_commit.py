"""The writer's side of a commit through the chunks' Raft logs (DESIGN §13).

The writer turns its transaction into a `Proposal` for the chunk and hands it to
the chunk's leader: itself, or the leader its group names, over the swarm port
(`RaftPropose`). The leader answers the conflicts its replica shows once the
entries in flight on the same items applied (`swarm/in_flight.py`), else appends
it; once the entry applies there (every holder decides it alike, `swarm/apply.py`)
it answers with the commit, or with the conflicts as a `ConflictError`. The
application's commit rules are checked here, over the whole transaction, first.

A transaction that writes several chunks commits in two phases across their
logs: `swarm/two_phase.py` decides what to propose, this module proposes it
(prepares one after the other, decisions in parallel) and feeds the answers back.
"""

from __future__ import annotations

import asyncio
import logging
import random
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from mapapi.core import codec
from mapapi.core.clock import LamportClock
from mapapi.core.errors import (
    ChunkBusy,
    CommitUncertain,
    ConflictError,
    MapError,
    NoQuorum,
    NotChunkLeader,
    PeerUnavailable,
    ProposalLost,
    RequestTimeout,
)
from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, CommitId, PeerId
from mapapi.core.proposal import LogEntry, Proposal, TimeFloor, TxDecision
from mapapi.core.transaction import Transaction
from mapapi.net.messages import RaftPropose, RaftProposed
from mapapi.net.rpc import Request, Rpc
from mapapi.store.offload import off_loop
from mapapi.swarm import faults
from mapapi.swarm.apply import Outcome
from mapapi.swarm.commit_check import CommitRule, checked_entry
from mapapi.swarm.group_apply import HEAVY_BYTES
from mapapi.swarm.groups import PROPOSE_TIMEOUT, RaftGroups
from mapapi.swarm.in_flight import InFlight
from mapapi.swarm.two_phase import Answer, TwoPhase

log = logging.getLogger(__name__)

BIG_CHANGES = 500
"""Changes from which a writer encodes its entry in a worker thread (`HEAVY_BYTES`)."""
RETRY_PAUSE, MAX_RETRY_PAUSE = 0.01, 0.2
"""Seconds before a proposal is made again after "busy" or "no leader" (doubling, to 0.2)."""


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
        rules: the application's commit rules, checked here over the whole
            transaction before it is proposed (they may read other chunks than the
            ones written, which holders of one chunk need not hold: a holder's
            decision depends on its replica of the chunk alone).
        answers: whether a peer was heard of lately (liveness); when most of a chunk's
            voters were not, a failed proposal or read names them (`NoQuorum`).
        label: how errors name a peer.
    """

    def __init__(
        self,
        groups: RaftGroups,
        rpc: Rpc,
        address: Callable[[PeerId], str],
        clock: LamportClock,
        rules: Sequence[CommitRule] = (),
        *,
        answers: Callable[[PeerId], bool] | None = None,
        label: Callable[[PeerId], str] = PeerId.__str__,
    ) -> None:
        self.groups = groups
        self.rpc = rpc
        self._address = address
        self.clock = clock
        self.rules = tuple(rules)
        self._answers = answers
        self._label = label
        self.in_flight = InFlight()
        self.acknowledged = 0  # the newest commit time acknowledged here (`Peer.now`)
        rpc.register(RaftPropose, self.rpc_raft_propose)

    async def commit(self, tx: Transaction, message: str) -> Committed:
        """Commit `tx` through the logs of the chunks it writes: one proposal for
        one chunk, a two-phase commit for several (`swarm/two_phase.py`).

        Raises:
            ConflictError: someone changed an item of `tx` since its begin time
                (mergeable here: it carries `tx`).
            UsageError: a commit rule refused the changes.
            ChunkBusy: another transaction kept a chunk prepared too long.
            NotChunkLeader, NoQuorum: no leader, or no majority of voters (retry).
            ProposalLost: a multi-chunk commit was aborted, not committed (retry).
            CommitUncertain: the entry was sent and its fate could not be learnt
                (a timeout, a leader gone), or a multi-chunk commit's decision.
        """
        if not tx.changes:
            return Committed(None, ())
        store = self.groups.store
        for rule in self.rules:  # over the whole transaction, on this peer's replicas,
            await off_loop(store, rule.check, store, tx.changes)  # in a worker (issue 14)
        chunks = self._chunks_of(tx)
        if len(chunks) < 2:
            (chunk,) = chunks
            proposal = Proposal.of(tx, chunk, message, self.clock.tick())
            try:
                outcome = await self.propose(chunk, proposal)
            except (RequestTimeout, PeerUnavailable) as exc:  # maybe taken: not to retry
                raise CommitUncertain(f"commit {proposal.commit_id.short}: {exc}") from exc
            if outcome.record is not None:
                await faults.reached("commit.acknowledged")
            return await self._done(tx, self._raise_failure(chunk, outcome, tx))
        time, commit_id = self.clock.tick(), CommitId.new()
        machine = TwoPhase(
            {c: Proposal.of(tx, c, message, time, chunks, commit_id) for c in chunks}
        )
        outcomes = await self._run(machine)
        if machine.committed:
            revisions = tuple(r for o in outcomes for r in o.revisions)
            record = next((o.record for o in outcomes if o.record is not None), None)
            return await self._done(tx, Outcome(record, revisions))
        if machine.uncertain and machine.decision is None:
            raise CommitUncertain(
                f"commit {commit_id.short} over {len(chunks)} chunks: {machine.uncertain}; "
                "its chunks' leaders settle it from the first chunk's log"
            )
        if machine.conflicts:
            raise ConflictError(list(machine.conflicts), tx, self.groups.store.raft_time(chunks[0]))
        if machine.busy:
            raise ChunkBusy(machine.busy)
        raise ProposalLost(f"commit {commit_id.short} was aborted: {machine.failed}; retry")

    def _chunks_of(self, tx: Transaction) -> tuple[ChunkId, ...]:
        """The chunks `tx` commits through, in id order: those it writes and, under
        serializable isolation, those whose items it read or scanned (their
        prepares validate the reads there and hold the chunk until the decision,
        so no write lands on what it read in between)."""
        chunks = {c.chunk_id for c in tx.changes}
        if tx.isolation == "serializable":
            store = self.groups.store
            for item in tx.read_set:
                read = store.item_chunk(item)
                if read is not None:
                    chunks.add(read)
            for table, scope in tx.scopes:
                chunks |= {scope} if scope is not None else {c.id for c in store.chunks(table)}
            chunks = {c for c in chunks if store.raft_applied_index(c) is not None}  # held here
            chunks |= {c.chunk_id for c in tx.changes}
        return tuple(sorted(chunks))

    async def _done(self, tx: Transaction, outcome: Outcome) -> Committed:
        if outcome.record is not None:
            self.clock.advance_to(outcome.record.time)
            self.acknowledged = max(self.acknowledged, outcome.record.time)
            await self._applied_here(outcome.record)
        tx.committed(list(outcome.revisions))
        return Committed(outcome.record, outcome.revisions)

    async def _applied_here(self, record: CommitRecord) -> None:
        """Wait until this peer's replicas of the commit's chunks applied it, so the
        writer reads its own writes (its store, its log, its next commit's rules):
        the leader answered once it applied the entry, and a follower applies it at
        the next append. A replica that stays behind (cut off from its leader right
        after) is left to catch up by itself after `PROPOSE_TIMEOUT`."""
        store = self.groups.store
        try:
            async with asyncio.timeout(PROPOSE_TIMEOUT):
                for chunk in record.chunks:
                    held = store.raft_applied_index(chunk) is not None
                    while held and store.raft_time(chunk) < record.time:
                        await self.groups.progressed(chunk)
        except TimeoutError:
            log.warning(
                "commit %s: this replica has not applied it yet; it catches up by itself",
                record.id.short,
            )

    async def _run(self, machine: TwoPhase) -> list[Outcome]:
        """Drive a two-phase commit to its end; the outcomes of its decisions."""
        decided: list[Outcome] = []
        step = machine.start()
        while step:
            if any(isinstance(e, TxDecision) and e.commit for _, e in step):
                await faults.reached("commit.prepared")
            answers = await asyncio.gather(*(self._answer(c, e) for c, e in step))
            step = []
            for chunk, answer, outcome in answers:
                if outcome is not None and outcome.decision is not None:
                    decided.append(outcome)
                step += machine.answered(chunk, answer)
        return decided

    async def _answer(
        self, chunk: ChunkId, entry: LogEntry
    ) -> tuple[ChunkId, Answer, Outcome | None]:
        try:
            outcome = await self.propose(chunk, entry)
        except ChunkBusy as exc:
            return chunk, Answer(busy=str(exc)), None
        except MapError as exc:
            return chunk, Answer(unknown=f"chunk {chunk.short}: {exc}"), None
        answer = Answer(outcome.prepared, outcome.conflicts, outcome.decision)
        return chunk, answer, outcome

    async def propose(
        self,
        chunk: ChunkId,
        entry: LogEntry,
        timeout: float = PROPOSE_TIMEOUT,  # noqa: ASYNC109
    ) -> Outcome:
        """Have `entry` applied through `chunk`'s log, by its leader (this peer or
        another), and return how it was decided. While the chunk has no known
        leader, or is held by another transaction's prepare, wait and ask again,
        up to `timeout`.

        Raises:
            ChunkBusy: the chunk stayed held by another transaction.
            NoQuorum: most of the chunk's voters do not answer (named).
            NotChunkLeader: no leader was known in time.
            RequestTimeout, NetworkError, ProposalLost: the entry's fate is unknown.
        """
        try:
            return await self._propose_retrying(chunk, entry, timeout)
        except (NotChunkLeader, RequestTimeout, PeerUnavailable) as exc:
            raise self._explained(chunk, exc) from exc

    async def _propose_retrying(
        self,
        chunk: ChunkId,
        entry: LogEntry,
        timeout: float,  # noqa: ASYNC109
    ) -> Outcome:
        if len(getattr(entry, "changes", ())) < BIG_CHANGES:
            data = codec.encode_entry(entry)
        else:  # a mission's rows: encoded in a worker (issue 14 §1)
            data = await off_loop(self.groups.store, codec.encode_entry, entry)
        deadline = asyncio.get_running_loop().time() + timeout
        pause = RETRY_PAUSE
        while True:
            try:
                outcome = await self._propose_once(chunk, entry, data)
                if not outcome.busy:
                    return outcome
                error: MapError = ChunkBusy(
                    f"chunk {chunk.short} stayed held by another transaction's two-phase "
                    f"commit for {timeout:g} s; retry"
                )
            except NotChunkLeader as exc:
                error = exc
            if asyncio.get_running_loop().time() + pause > deadline:
                raise error
            await asyncio.sleep(pause * (0.5 + random.random()))
            pause = min(pause * 2, MAX_RETRY_PAUSE)

    async def read_at(self, chunk: ChunkId, time: int, timeout: float = PROPOSE_TIMEOUT) -> None:  # noqa: ASYNC109
        """Make this replica of `chunk` read at `time` as every replica will from now
        on: catch up with the leader (ReadIndex), and if the chunk's clock is still
        behind `time`, close its log there with a `TimeFloor`, so every commit
        applied later is stamped past `time` and a view reading at `time` sees a
        state that never changes, and every change after it as a conflict.

        Raises:
            NotChunkLeader: no leader was known in time.
            ChunkBusy: a multi-chunk transaction held the chunk too long.
            RequestTimeout: the leader could not confirm in time.
        """
        if await self.caught_up(chunk, timeout) >= time:
            return
        await self.propose(chunk, TimeFloor(time), timeout)
        await self.caught_up(chunk, timeout)  # the floor applied here too

    async def caught_up(self, chunk: ChunkId, timeout: float = PROPOSE_TIMEOUT) -> int:  # noqa: ASYNC109
        """Catch this replica of `chunk` up with its leader (`RaftGroups.catch_up`,
        asking again while an election runs); returns the chunk's clock then: no
        commit applied later is stamped at or before it.

        Raises:
            NoQuorum: most of the chunk's voters do not answer (named).
            NotChunkLeader: no leader was known in time.
            RequestTimeout: the leader could not confirm in time.
        """
        deadline = asyncio.get_running_loop().time() + timeout
        while True:
            try:
                await self.groups.catch_up(chunk, timeout)
                return self.groups.store.raft_time(chunk)
            except NotChunkLeader as exc:
                if asyncio.get_running_loop().time() + MAX_RETRY_PAUSE > deadline:
                    raise self._explained(chunk, exc) from exc
                await asyncio.sleep(MAX_RETRY_PAUSE * random.random())
            except RequestTimeout as exc:
                raise self._explained(chunk, exc) from exc

    def _explained(self, chunk: ChunkId, error: MapError) -> MapError:
        """`error`, or, when most of the chunk's voters do not answer here (a
        minority cannot commit, DESIGN §13), a `NoQuorum` naming those voters."""
        if self._answers is None:
            return error
        try:
            voters = self.groups.mail.peers(self.groups.config(chunk).voters)
        except NotChunkLeader:  # not a member (any more)
            return error
        if not voters:  # no configuration yet (joined, not caught up): nothing to name
            return error
        down = [p for p in voters if p != self.groups.me and not self._answers(p)]
        if len(voters) - len(down) > len(voters) // 2:
            return error
        return NoQuorum.of(chunk, len(voters), [self._label(p) for p in down])

    async def _propose_once(self, chunk: ChunkId, entry: LogEntry, data: bytes) -> Outcome:
        if self.groups.is_leader(chunk):
            return await self.in_flight.propose(
                self.groups, chunk, entry, data, heavy=len(data) >= HEAVY_BYTES
            )
        leader = self.groups.leader(chunk)
        if leader is None:
            raise NotChunkLeader.of(chunk, None)
        try:
            answer = await self.call_raft_propose(leader, chunk, data)
        except ConflictError as exc:
            return Outcome(conflicts=tuple(exc.conflicts))
        decision = None
        if answer.decided and not isinstance(entry, TimeFloor):
            decision = TxDecision(entry.commit_id, answer.commit, answer.time)
        record, revisions, busy = answer.record, answer.revisions, answer.busy
        return Outcome(record, revisions, busy=busy, prepared=answer.prepared, decision=decision)

    def _raise_failure(
        self, chunk: ChunkId, outcome: Outcome, tx: Transaction | None = None
    ) -> Outcome:
        """`outcome`, unless it is a failure: then its error (mergeable into `tx`)."""
        if outcome.conflicts:
            raise ConflictError(list(outcome.conflicts), tx, self.groups.store.raft_time(chunk))
        return outcome

    async def call_raft_propose(self, leader: PeerId, chunk: ChunkId, data: bytes) -> RaftProposed:
        """Ask `leader` to propose `data` to `chunk`'s log and wait for it to apply."""
        body = RaftPropose(chunk, data)
        return await self.rpc.request(
            self._address(leader), body, timeout=PROPOSE_TIMEOUT + 1.0, expect=RaftProposed
        )

    async def rpc_raft_propose(self, req: Request) -> RaftProposed:
        """Propose a writer's entry as this chunk's leader; answer once applied.

        Raises:
            NotChunkLeader: this peer does not lead the chunk (the writer asks again).
            CorruptRepoError: the entry does not parse.
            NotParticipatingError, UsageError: an entry that would break the store
                (`check_proposal`).
            ConflictError: how the holders decided a proposal.
        """
        body: RaftPropose = req.body
        if not self.groups.is_leader(body.chunk):
            raise NotChunkLeader.of(body.chunk, self.groups.leader(body.chunk))
        members = {self.groups.me, *self.groups.members(body.chunk)}
        args = (self.groups.store, body.chunk, body.proposal, req.sender, members, self.clock.now())
        if heavy := len(body.proposal) >= HEAVY_BYTES:  # a mission's rows: in a worker
            entry = await off_loop(self.groups.store, checked_entry, *args)  # (issue 14 §1)
        else:
            entry = checked_entry(*args)
        applied = await self.in_flight.propose(
            self.groups, body.chunk, entry, body.proposal, heavy=heavy
        )
        outcome = self._raise_failure(body.chunk, applied)
        d = outcome.decision
        return RaftProposed(
            outcome.record,
            outcome.revisions,
            outcome.prepared,
            outcome.busy,
            d is not None,
            d is not None and d.commit,
            0 if d is None else d.time,
        )
