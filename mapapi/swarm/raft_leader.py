"""The leader's half of a Raft node: replication, commit, CheckQuorum and ReadIndex.

Pure (DESIGN §13). `RaftNode` (in `raft.py`) inherits it, through `Follower` (`raft_follower.py`);
the split only keeps modules short.
Citations as in `raft.py`.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable

from .raft_log import RaftLog
from .raft_progress import Progress, ProgressState, ReadOnly, ReadRequest
from .raft_types import (
    NONE,
    Config,
    Entry,
    EntryKind,
    Message,
    MessageKind,
    NotLeader,
    RaftOptions,
    ReadState,
    Role,
    Snapshot,
)

log = logging.getLogger(__name__)

M = MessageKind


class Leader:
    """State and steps of a node while it leads; see `RaftNode` for the public API."""

    id: int
    term: int
    role: Role
    leader: int
    config: Config
    options: RaftOptions
    log: RaftLog
    _progress: dict[int, Progress]
    _read_only: ReadOnly
    _early_reads: list[ReadRequest]
    _read_states: list[ReadState]
    _msgs: list[Message]
    _election_elapsed: int
    _heartbeat_elapsed: int
    quiet: bool
    _pending_conf_index: int

    def _become_follower(self, term: int, leader: int) -> None:
        raise NotImplementedError

    def _committed(self, old: int) -> None:
        raise NotImplementedError

    def _sync_config(self) -> None:
        raise NotImplementedError

    def lacking(self, index: int) -> list[int]:
        """The other voters that, as far as this leader knows, have not persisted
        entry `index` (none when this node does not lead): who keeps it uncommitted."""
        if self.role is not Role.LEADER:
            return []
        voters = sorted(self.config.voters - {self.id})
        return [n for n in voters if n in self._progress and self._progress[n].match < index]

    def caught_up_learners(self) -> frozenset[int]:
        """The learners that, as far as this leader knows, hold every committed entry
        (none when this node does not lead): those it may promote to voters (thesis
        §4.2.1: a new server catches up before it counts, so a member that never
        answers never gets a vote)."""
        if self.role is not Role.LEADER:
            return frozenset()
        committed = self.log.committed
        return frozenset(
            n
            for n in self.config.learners
            if n in self._progress and self._progress[n].match >= committed
        )

    # -- leader (paper §5.3) -----------------------------------------------------------------

    def _tick_leader(self) -> None:
        if self.quiet:
            return  # no heartbeats, no CheckQuorum: the followers are quiet too
        self._heartbeat_elapsed += 1
        self._election_elapsed += 1
        for pr in self._progress.values():
            if pr.state is ProgressState.SNAPSHOT:
                pr.snapshot_ticks += 1
                if pr.snapshot_ticks >= self.options.election_tick:
                    pr.pending_snapshot = 0  # presumed lost: probe again
                    pr.become_probe()
        if self._election_elapsed >= self.options.election_tick:
            self._election_elapsed = 0
            if self.options.check_quorum:
                active = {n for n, pr in self._progress.items() if pr.recent_active}
                if not self.config.has_quorum(active | {self.id}):
                    # CheckQuorum (thesis §6.2): we may be cut off; let the majority move on.
                    log.debug("node %d lost its quorum in term %d", self.id, self.term)
                    self._become_follower(self.term, NONE)
                    return
                for node, pr in self._progress.items():
                    pr.recent_active = node == self.id
        if self._heartbeat_elapsed >= self.options.heartbeat_tick:
            self._heartbeat_elapsed = 0
            if self.options.quiesce and self._idle():
                self._quiesce()
                return
            self._bcast_heartbeat(self._read_only.last_context())

    def _idle(self) -> bool:
        """Whether nothing is left to do: every member holds and applied every entry
        (as far as this leader knows, and heard from in this election interval), and
        no read or membership change waits."""
        log_ = self.log
        return (
            log_.committed == log_.last_index
            and log_.applied >= log_.committed
            and self._pending_conf_index <= log_.committed
            and not self._read_only.last_context()
            and not self._early_reads
            and all(
                pr.match == log_.last_index and pr.recent_active for pr in self._progress.values()
            )
        )

    def _quiesce(self) -> None:
        """Tell every member to go quiet, and stop heartbeats."""
        for node in sorted(self._progress):
            if node != self.id:
                commit = min(self._progress[node].match, self.log.committed)
                self._send(M.QUIESCE, node, commit=commit)
        self.quiet = True

    def _wake(self) -> None:
        """Leave quiet (a proposal, a read, a message): heartbeats resume at the next
        tick, and CheckQuorum counts every member as heard from until then (they were
        silent because we asked them to be)."""
        if not self.quiet:
            return
        self.quiet = False
        self._election_elapsed = 0
        self._heartbeat_elapsed = self.options.heartbeat_tick
        for pr in self._progress.values():
            pr.recent_active = True

    def _propose(self, kind: EntryKind, data: bytes) -> tuple[int, int]:
        if self.role is not Role.LEADER:
            raise NotLeader(self.leader)
        self._wake()
        entry = Entry(self.term, self.log.last_index + 1, kind, data)
        self._append([entry])
        return entry.index, entry.term

    def _append(self, entries: list[Entry]) -> None:
        self.log.append(entries)
        self._progress[self.id].maybe_update(self.log.last_index)
        self._sync_config()
        if self.role is Role.LEADER and not self._maybe_commit():
            self._bcast_append()

    def _maybe_commit(self) -> bool:
        """Commit the highest index a quorum of voters holds, if it is of our term (§5.4.2)."""
        matches = sorted(
            (pr.match for n, pr in self._progress.items() if n in self.config.voters), reverse=True
        )
        quorum = self.config.quorum()
        if len(matches) < quorum:
            return False
        index = matches[quorum - 1]
        if index <= self.log.committed or self.log.term(index) != self.term:
            return False
        old = self.log.committed
        self.log.commit_to(index)
        self._bcast_append()  # tell followers the new commit index before stepping down
        self._committed(old)
        return True

    def _bcast_append(self) -> None:
        for node in sorted(self._progress):
            if node != self.id:
                self._send_append(node)

    def _bcast_heartbeat(self, context: bytes, *, voters_only: bool = False) -> None:
        to = self.config.voters if voters_only else self._progress
        for node in sorted(to):
            if node != self.id and node in self._progress:
                commit = min(self._progress[node].match, self.log.committed)
                self._send(M.HEARTBEAT, node, commit=commit, context=context)

    def _send_append(self, node: int, send_empty: bool = True) -> bool:
        """Send `node` what it lacks (an append, or the snapshot); whether a message went."""
        pr = self._progress[node]
        if pr.is_paused(self.options.max_inflight):
            return False
        prev = pr.next - 1
        prev_term = self.log.term(prev)
        if prev_term is None:
            # The entries it needs are compacted away: send the snapshot (paper §7).
            snap = self.log.snapshot
            pr.become_snapshot(snap.index)
            self._send(M.SNAP, node, snapshot=snap)
            return True
        opts = self.options
        entries = self.log.slice(pr.next, opts.max_entries_per_msg, opts.max_bytes_per_msg)
        if not entries and not send_empty:
            return False
        pr.sent(entries[-1].index if entries else prev, len(entries))
        self._send(
            M.APP,
            node,
            index=prev,
            log_term=prev_term,
            entries=tuple(entries),
            commit=self.log.committed,
        )
        return True

    def _step_leader(self, m: Message) -> None:
        pr = self._progress.get(m.sender)
        if m.kind is M.READ_INDEX:
            self._leader_read(ReadRequest(self.log.committed, m.context, m.sender))
        if pr is None:
            return
        if m.kind is M.APP_RESP:
            pr.recent_active = True
            self._handle_append_response(m, pr)
        elif m.kind is M.HEARTBEAT_RESP:
            pr.recent_active = True
            pr.probe_sent = False
            if pr.state is ProgressState.REPLICATE and pr.inflights:
                pr.inflights.popleft()  # an ack may be lost: let one more append through
            if pr.match < self.log.last_index:
                self._send_append(m.sender)
            acks = self._read_only.ack(m.context, m.sender) if m.context else None
            if acks is not None and self.config.has_quorum(acks):
                for request in self._read_only.release(m.context):
                    self._answer_read(request)
                if waiting := self._read_only.last_context():  # came in during the round
                    self._bcast_heartbeat(waiting, voters_only=True)

    def _handle_append_response(self, m: Message, pr: Progress) -> None:
        if m.reject:
            # Fast backtracking: skip to the follower's hint, then past every entry of ours
            # whose term is above the follower's term there (thesis §5.3 optimisation).
            hint = m.reject_hint
            if m.log_term > 0:
                hint, _ = self.log.find_conflict_by_term(hint, m.log_term)
            if pr.maybe_decr_to(m.index, hint):
                if pr.state is ProgressState.REPLICATE:
                    pr.become_probe()
                self._send_append(m.sender)
            return
        was_paused = pr.is_paused(self.options.max_inflight)
        if not pr.maybe_update(m.index):
            return
        if pr.state is ProgressState.PROBE:
            pr.become_replicate()
        elif pr.state is ProgressState.SNAPSHOT and pr.match >= pr.pending_snapshot:
            pr.become_probe()
            pr.become_replicate()
        else:
            pr.free_to(m.index)
        if not self._maybe_commit() and was_paused:
            self._send_append(m.sender)
        while m.sender in self._progress and self._send_append(m.sender, send_empty=False):
            pass

    # -- ReadIndex (thesis §6.4) -------------------------------------------------------------

    def _leader_read(self, request: ReadRequest) -> None:
        if self.log.term(self.log.committed) != self.term:
            self._early_reads.append(request)  # until our no-op commits, commit may be stale
        elif self.config.voters == {self.id}:
            self._answer_read(request)
        else:
            # One round of heartbeats at a time, to the voters (only theirs count):
            # reads that come in meanwhile wait for the next, which confirms them all.
            round_out = bool(self._read_only.last_context())
            self._read_only.add(request)
            self._read_only.ack(request.context, self.id)
            if not round_out:
                self._bcast_heartbeat(request.context, voters_only=True)

    def _answer_read(self, request: ReadRequest) -> None:
        if request.requester == self.id:
            self._read_states.append(ReadState(request.index, request.context))
        else:
            self._send(
                M.READ_INDEX_RESP, request.requester, index=request.index, context=request.context
            )

    def _send(
        self,
        kind: MessageKind,
        to: int,
        *,
        index: int = 0,
        log_term: int = 0,
        entries: Iterable[Entry] = (),
        commit: int = 0,
        reject: bool = False,
        reject_hint: int = 0,
        snapshot: Snapshot | None = None,
        context: bytes = b"",
    ) -> None:
        self._msgs.append(
            Message(
                kind,
                self.id,
                to,
                self.term,
                log_term,
                index,
                tuple(entries),
                commit,
                reject,
                reject_hint,
                snapshot,
                context,
            )
        )
