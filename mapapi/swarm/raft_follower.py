"""A follower's and a candidate's half of a Raft node: elections (paper §5.2, PreVote) and
what a leader sends (appends, heartbeats, snapshots).

Pure (DESIGN §13). `RaftNode` (in `raft.py`) inherits it, and it the leader's half
(`raft_leader.py`); the split only keeps modules short. Citations as in `raft.py`.
"""

from __future__ import annotations

import logging
import random

from .raft_leader import Leader
from .raft_types import NONE, Message, MessageKind, ReadState, Role

log = logging.getLogger(__name__)

M = MessageKind
VOTE_RESPONSE = {M.VOTE: M.VOTE_RESP, M.PRE_VOTE: M.PRE_VOTE_RESP}
"""The answer to each kind of vote request."""


class Follower(Leader):
    """Steps of a node while it follows or campaigns; see `RaftNode` for the public API."""

    vote: int
    _votes: dict[int, bool]
    _rng: random.Random

    def _reset(self, term: int) -> None:
        raise NotImplementedError

    def _become_leader(self) -> None:
        raise NotImplementedError

    def _commit_to(self, index: int) -> None:
        raise NotImplementedError

    def _promotable(self) -> bool:
        # A voter removed by a change not yet committed may still be needed to commit it, so
        # it may campaign; its own vote does not count (thesis §4.2.2).
        log_ = self.log
        return self.id in self.config.voters or (
            log_.config_index > log_.committed and self.id in log_.previous_config.voters
        )

    def _in_lease(self) -> bool:
        return (
            self.options.check_quorum
            and self.leader != NONE
            and self._election_elapsed < self.options.election_tick
        )

    def _campaign(self, pre: bool) -> None:
        if pre:
            # PreVote (thesis §9.6): poll for term+1 without raising our own term.
            self._reset(self.term)
            self.role = Role.PRE_CANDIDATE
            kind, term = M.PRE_VOTE, self.term + 1
        else:
            self._reset(self.term + 1)
            self.role, self.vote = Role.CANDIDATE, self.id
            kind, term = M.VOTE, self.term
        self._votes[self.id] = True
        if self._poll():
            return
        for node in sorted(self.config.voters - {self.id}):
            self._msgs.append(
                Message(
                    kind,
                    self.id,
                    node,
                    term,
                    log_term=self.log.last_term(),
                    index=self.log.last_index,
                )
            )

    def _poll(self) -> bool:
        """Count the votes; act on a result. Whether the election ended."""
        granted = {n for n, ok in self._votes.items() if ok}
        refused = {n for n, ok in self._votes.items() if not ok}
        if self.config.has_quorum(granted):
            if self.role is Role.PRE_CANDIDATE:
                self._campaign(pre=False)
            else:
                self._become_leader()
            return True
        if len(self.config.voters - refused) < self.config.quorum():
            self._become_follower(self.term, NONE)
            return True
        return False

    def _handle_vote_request(self, m: Message) -> None:
        # Paper Fig. 2 RequestVote: one vote per term, only for a log at least as up to date
        # as ours (§5.4.1). A pre-vote for a higher term promises nothing, so it is free.
        can_vote = (
            self.vote == m.sender
            or (self.vote == NONE and self.leader == NONE)
            or (m.kind is M.PRE_VOTE and m.term > self.term)
        )
        if can_vote and self.log.is_up_to_date(m.index, m.log_term):
            self._msgs.append(Message(VOTE_RESPONSE[m.kind], self.id, m.sender, m.term))
            if m.kind is M.VOTE:
                self._election_elapsed = 0
                self.vote = m.sender
        else:
            self._send(VOTE_RESPONSE[m.kind], m.sender, reject=True)

    def _step_candidate(self, m: Message) -> None:
        if m.kind in (M.APP, M.HEARTBEAT, M.SNAP, M.QUIESCE):
            self._become_follower(self.term, m.sender)
            self._step_follower(m)
            return
        expected = M.PRE_VOTE_RESP if self.role is Role.PRE_CANDIDATE else M.VOTE_RESP
        if m.kind is expected:
            self._votes.setdefault(m.sender, not m.reject)
            self._poll()

    def _step_follower(self, m: Message) -> None:
        if m.kind in (M.APP, M.HEARTBEAT, M.SNAP, M.QUIESCE):
            self._election_elapsed = 0
            self.leader = m.sender
            self.quiet = m.kind is M.QUIESCE
        if m.kind is M.QUIESCE:
            self._commit_to(m.commit)  # no answer: an answer would wake the leader
        elif m.kind is M.APP:
            self._handle_append(m)
        elif m.kind is M.HEARTBEAT:
            self._commit_to(m.commit)
            self._send(M.HEARTBEAT_RESP, m.sender, context=m.context)
        elif m.kind is M.SNAP:
            self._handle_snapshot(m)
        elif m.kind is M.READ_INDEX_RESP:
            self._read_states.append(ReadState(m.index, m.context))

    def _handle_append(self, m: Message) -> None:
        if m.index < self.log.committed:
            self._send(M.APP_RESP, m.sender, index=self.log.committed)
            return
        last_new = self.log.maybe_append(m.index, m.log_term, m.commit, m.entries)
        if last_new is not None:
            self._sync_config()
            self._send(M.APP_RESP, m.sender, index=last_new)
            return
        hint, hint_term = self.log.find_conflict_by_term(m.index, m.log_term)
        self._send(
            M.APP_RESP, m.sender, index=m.index, reject=True, reject_hint=hint, log_term=hint_term
        )

    def _handle_snapshot(self, m: Message) -> None:
        snap = m.snapshot
        assert snap is not None
        if snap.index <= self.log.committed:
            pass  # stale or duplicate
        elif self.log.match_term(snap.index, snap.term):
            self._commit_to(snap.index)  # we hold the snapshot's entries: just commit them
        else:
            self.log.restore(snap)
            self._sync_config()
            log.debug("node %d restored snapshot %d/%d", self.id, snap.index, snap.term)
        # Acknowledge only what is committed: entries beyond may still diverge from the leader.
        self._send(M.APP_RESP, m.sender, index=self.log.committed)
