"""The Raft state machine of one group member: ticks, messages and proposals in, `Ready` out.

Pure (DESIGN §13): standard library only, no I/O, no clock, no threads. Time is `tick()`;
randomness is an injected `random.Random`. The driver loop is etcd-io/raft's `Ready` loop:

    node.tick() / node.step(msg) / node.propose(data) ...
    if node.has_ready():
        rd = node.ready()
        persist(rd); send(rd.messages); apply(rd); node.advance(rd)

Design choices (thesis = Ongaro, "Consensus: Bridging Theory and Practice", 2014):
- PreVote (thesis §9.6): a node whose election timer fires first asks whether it *could* win
  at term+1, without raising its term; only on a majority does it start a real election.
- CheckQuorum (thesis §6.2, §9.6): a leader that has not heard from a majority of voters within
  an election timeout steps down; a node that heard from a leader within an election timeout
  ignores (pre)vote requests (leader lease), so a node back from a pause or a partition cannot
  depose a healthy leader.
- Membership changes are single-server (thesis §4.1) and take effect as soon as the entry is
  *appended* to a node's log, committed or not; a truncated change is rolled back. (Applying on
  commit, as etcd does, deadlocked the simulator: a leader that removed itself stepped down with
  a longer log than the last voter, which never learnt the commit and so still counted the old
  leader's vote.) A leader proposes one change at a time and none before it has committed an
  entry of its own term (the fix to the single-server bug, Ongaro's raft-dev errata, 2015). A
  leader that removes itself keeps leading, without counting itself, until the removal commits,
  then steps down (thesis §4.2.2).
- Learners receive the log but never campaign and never count in a quorum (for commit, votes or
  CheckQuorum). A learner still answers vote requests: a candidate that already knows of the
  learner's promotion counts its vote, and refusing could block elections (etcd does the same).
- ReadIndex (thesis §6.4): the leader records its commit index, confirms leadership with a round
  of heartbeats, then hands out a `ReadState`; followers forward to the leader.
"""

from __future__ import annotations

import logging
import random

from .raft_follower import VOTE_RESPONSE, Follower
from .raft_log import RaftLog
from .raft_progress import Progress, ProgressState, ReadOnly, ReadRequest
from .raft_types import (
    NONE,
    ConfChange,
    Entry,
    EntryKind,
    HardState,
    Message,
    MessageKind,
    NotLeader,
    PersistentState,
    ProposalRefused,
    RaftOptions,
    ReadState,
    Ready,
    Role,
    Snapshot,
)

log = logging.getLogger(__name__)

M = MessageKind
__all__ = ["RaftNode", "RaftOptions"]


class RaftNode(Follower):
    """One member of one Raft group.

    Args:
        node_id: this node's id (> 0).
        state: what it persisted before (`PersistentState.bootstrap(config)` for a founding
            member, `PersistentState()` for a node that joins and learns the log from a leader).
        rng: the source of randomised election timeouts (paper §5.2).
        options: timeouts and limits.
        applied: the index the state machine already holds (default: the snapshot's).
    """

    def __init__(
        self,
        node_id: int,
        state: PersistentState,
        rng: random.Random,
        options: RaftOptions | None = None,
        applied: int = 0,
    ) -> None:
        assert node_id != NONE
        self.id = node_id
        self.options = options or RaftOptions()
        self._rng = rng
        hs = state.hard_state
        self.log = RaftLog(state.snapshot, state.entries, hs.commit, applied)
        self.config = self.log.config
        self.term, self.vote = hs.term, hs.vote
        self.role = Role.FOLLOWER
        self.leader = NONE
        self._persisted = HardState(hs.term, hs.vote, self.log.committed)
        self._msgs: list[Message] = []
        self._read_states: list[ReadState] = []
        self._votes: dict[int, bool] = {}
        self._progress: dict[int, Progress] = {}
        self._read_only = ReadOnly()
        self._early_reads: list[ReadRequest] = []  # before this leader committed in its term
        self._pending_conf_index = 0
        self._outstanding = False
        self._election_elapsed = self._heartbeat_elapsed = 0
        self._timeout = self.options.election_tick
        self.quiet = False  # an idle group: no heartbeats, no election timer (see `tick`)
        self._reset(self.term)

    # -- inputs ------------------------------------------------------------------------------

    def tick(self, leader_alive: bool = True) -> None:
        """Advance logical time by one tick.

        With `RaftOptions.quiesce`, a leader whose followers all hold every entry
        tells them to go quiet and stops sending heartbeats; a quiet follower keeps
        its election timer stopped while `leader_alive` (the driver's peer-level
        failure detector still hears the leader's peer), so a thousand idle groups
        cost nothing. Any proposal, read or message wakes the group again.
        """
        if self.role is Role.LEADER:
            self._tick_leader()
            return
        if self.quiet:
            if leader_alive:
                return
            self.quiet = False  # the leader's peer went silent: the timer runs again
        self._election_elapsed += 1
        if self._promotable() and self._election_elapsed >= self._timeout:
            self._election_elapsed = 0
            self._campaign(pre=self.options.pre_vote)

    def wake(self) -> None:
        """Leave quiet: a leader heartbeats again (a member that restarted lost who
        leads; it learns it from the next heartbeat), a follower's timer runs."""
        if self.role is Role.LEADER:
            self._wake()
        else:
            self.quiet = False

    def campaign(self) -> None:
        """Start an election now (as if the election timer fired), if this node is a voter."""
        if self.role is not Role.LEADER and self._promotable():
            self._campaign(pre=self.options.pre_vote)

    def propose(self, data: bytes) -> tuple[int, int]:
        """Append a normal entry, as leader.

        Returns:
            (index, term) of the entry: it is committed once an entry at `index` with `term`
            comes out in `Ready.committed_entries`; another term there means it was lost.

        Raises:
            NotLeader: this node does not lead; `err.leader` names the leader it knows.
        """
        return self._propose(EntryKind.NORMAL, data)

    def propose_conf_change(self, change: ConfChange) -> tuple[int, int]:
        """Propose a single-server membership change, as leader; see `propose`.

        Raises:
            NotLeader: as for `propose`.
            ProposalRefused: a change is still uncommitted, or this leader has not yet
                committed an entry of its term.
            ValueError: the change does not apply to the current config.
        """
        if self.role is not Role.LEADER:
            raise NotLeader(self.leader)
        if self._pending_conf_index > self.log.committed:
            raise ProposalRefused("a membership change is in progress; retry when it commits")
        new = self.config.apply(change)
        index, term = self._propose(EntryKind.CONF_CHANGE, new.encode())
        self._pending_conf_index = index
        return index, term

    def read_index(self, context: bytes) -> None:
        """Ask for a linearizable read point; it comes back as a `ReadState` with `context`.

        `context` must be unique among the reads in flight in the group (e.g. node id and a
        counter). A read lost with a leader change never comes back: retry after a timeout.

        Raises:
            NotLeader: no leader is known to forward to.
        """
        if self.role is Role.LEADER:
            self._wake()
            self._leader_read(ReadRequest(self.log.committed, context, self.id))
        elif self.leader == NONE:
            raise NotLeader(NONE)
        else:
            self._send(M.READ_INDEX, self.leader, context=context)

    def step(self, m: Message) -> None:
        """Handle a message from another member (any order, duplicates, stale terms)."""
        if self.quiet and self.role is Role.LEADER:
            self._wake()  # a follower speaks: it missed the quiesce, or wants something
        if m.term > self.term:
            if m.kind in VOTE_RESPONSE and self._in_lease():
                # A leader was heard from within the election timeout: ignore a disruptive
                # candidate, without raising the term (thesis §4.2.3, §9.6).
                return
            if m.kind is M.PRE_VOTE or (m.kind is M.PRE_VOTE_RESP and not m.reject):
                pass  # a pre-vote never changes terms: m.term is the one it would run for
            elif m.kind in (M.APP, M.HEARTBEAT, M.SNAP, M.QUIESCE):
                self._become_follower(m.term, m.sender)
            else:
                self._become_follower(m.term, NONE)
        elif m.term < self.term:
            if m.kind in (M.APP, M.HEARTBEAT, M.QUIESCE):
                # A stale leader, perhaps cut off while we raised our term; with CheckQuorum
                # we would not raise it on its vote requests, so tell it our term instead.
                self._send(M.APP_RESP, m.sender)
            elif m.kind is M.PRE_VOTE:
                self._send(M.PRE_VOTE_RESP, m.sender, reject=True)
            return
        if m.kind in VOTE_RESPONSE:
            self._handle_vote_request(m)
        elif self.role is Role.LEADER:
            self._step_leader(m)
        elif self.role is Role.FOLLOWER:
            self._step_follower(m)
        else:
            self._step_candidate(m)

    def compact(self, index: int, data: bytes) -> Snapshot:
        """Replace the log up to an applied `index` by the application's state `data`.

        Returns:
            the snapshot, for the driver to persist before deleting the entries up to `index`;
            followers too far behind are sent it (paper §7).
        """
        term = self.log.term(index)
        if term is None or not self.log.snapshot.index < index <= self.log.applied:
            raise ValueError(f"cannot compact to {index}: not an applied entry in the log")
        snapshot = Snapshot(index, term, self.log.config_at(index), data)
        self.log.compact(snapshot)
        return snapshot

    def report_snapshot(self, node: int, ok: bool) -> None:
        """The driver learnt whether sending a snapshot to `node` finished (optional)."""
        pr = self._progress.get(node)
        if self.role is Role.LEADER and pr and pr.state is ProgressState.SNAPSHOT:
            if not ok:
                pr.pending_snapshot = 0
            pr.become_probe()

    # -- outputs -----------------------------------------------------------------------------

    def has_ready(self) -> bool:
        """Whether `ready()` has anything to do."""
        return bool(
            self._msgs
            or self._read_states
            or self.log.pending_snapshot
            or self.log.stable < self.log.last_index
            or self._hard_state() != self._persisted
            or self.log.unapplied_entries()
        )

    def ready(self) -> Ready:
        """What to persist, send and apply now; see `Ready` for the order contract.

        Raises:
            RuntimeError: the previous `Ready` was not `advance`d.
        """
        if self._outstanding:
            raise RuntimeError("advance() the previous Ready before asking for the next")
        self._outstanding = True
        hs = self._hard_state()
        rd = Ready(
            hard_state=hs if hs != self._persisted else None,
            entries=self.log.unstable_entries(),
            snapshot=self.log.pending_snapshot,
            messages=tuple(self._msgs),
            committed_entries=self.log.unapplied_entries(),
            read_states=tuple(self._read_states),
            role=self.role,
            leader=self.leader,
        )
        self._msgs.clear()
        self._read_states.clear()
        return rd

    def advance(self, rd: Ready) -> None:
        """The driver persisted, sent and applied everything in `rd`."""
        self._outstanding = False
        if rd.hard_state:
            self._persisted = rd.hard_state
        if rd.snapshot and self.log.pending_snapshot == rd.snapshot:
            self.log.pending_snapshot = None
        if rd.snapshot:
            self.log.applied = max(self.log.applied, rd.snapshot.index)
        if rd.entries:
            self.log.stable_to(rd.entries[-1].index, rd.entries[-1].term)
        if rd.committed_entries:
            self.log.applied = max(self.log.applied, rd.committed_entries[-1].index)

    # -- roles (paper §5.2) ------------------------------------------------------------------

    def _reset(self, term: int) -> None:
        if term != self.term:
            self.term, self.vote = term, NONE
        self.leader = NONE
        self.quiet = False
        self._election_elapsed = self._heartbeat_elapsed = 0
        # Randomised timeouts in [T, 2T) make split votes rare (paper §5.2).
        n = self.options.election_tick
        self._timeout = n + self._rng.randrange(n)
        self._votes.clear()
        self._progress.clear()
        self._read_only = ReadOnly()
        self._early_reads.clear()

    def _become_follower(self, term: int, leader: int) -> None:
        self._reset(term)
        self.role, self.leader = Role.FOLLOWER, leader

    def _become_leader(self) -> None:
        self._reset(self.term)
        self.role, self.leader = Role.LEADER, self.id
        for node in self.config.members | {self.id}:
            self._progress[node] = Progress(
                next=self.log.last_index + 1, recent_active=node == self.id
            )
        # An entry of our own term lets us commit the earlier ones (paper §5.4.2, thesis §6.4);
        # no membership change until it commits (the single-server fix, thesis §4.1 errata).
        self._pending_conf_index = self.log.last_index + 1
        self._append([Entry(self.term, self.log.last_index + 1, EntryKind.NOOP)])
        log.debug("node %d leads term %d", self.id, self.term)

    # -- commit and configuration ------------------------------------------------------------

    def _commit_to(self, index: int) -> None:
        old = self.log.committed
        self.log.commit_to(index)
        self._committed(old)

    def _committed(self, old: int) -> None:
        """Entries (`old`, commit] just committed."""
        if self.log.committed == old or self.role is not Role.LEADER:
            return
        if self.id not in self.config.voters and self.log.committed >= self.log.config_index:
            # Our own removal committed: step down; the rest elect a leader (thesis §4.2.2).
            log.debug("node %d removed while leading term %d: stepping down", self.id, self.term)
            self._become_follower(self.term, NONE)
            return
        if self.log.term(self.log.committed) == self.term:
            early, self._early_reads = self._early_reads, []
            for request in early:
                self._leader_read(
                    ReadRequest(self.log.committed, request.context, request.requester)
                )

    def _sync_config(self) -> None:
        """The log changed: adopt the last configuration in it (thesis §4.1)."""
        config = self.log.config
        if config == self.config:
            return
        self.config = config
        if self.role is not Role.LEADER:
            if self.role is not Role.FOLLOWER and not self._promotable():
                self._become_follower(self.term, NONE)
            return
        for node in list(self._progress):
            if node not in config.members and node != self.id:
                del self._progress[node]
        for node in sorted(config.members - set(self._progress)):
            self._progress[node] = Progress(next=self.log.last_index + 1, recent_active=True)
            self._send_append(node)
        self._maybe_commit()  # a smaller quorum may already hold more

    # -- helpers -----------------------------------------------------------------------------

    def _hard_state(self) -> HardState:
        return HardState(self.term, self.vote, self.log.committed)
