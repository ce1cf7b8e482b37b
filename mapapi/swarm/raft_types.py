"""Raft values: entries, configurations, snapshots, messages and the `Ready` record.

Pure (DESIGN §13): standard library only, no I/O. Node ids are positive ints; `NONE` (0)
means "no node" (no vote, no known leader). Citations are to Ongaro's thesis, "Consensus:
Bridging Theory and Practice" (2014), and the Raft paper (Ongaro & Ousterhout, 2014).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

NONE = 0
"""The id of no node: an empty vote, an unknown leader."""


@dataclass(frozen=True, slots=True)
class RaftOptions:
    """Tunables, in ticks and counts (etcd's defaults: heartbeat 1, election 10)."""

    election_tick: int = 10
    heartbeat_tick: int = 1
    pre_vote: bool = True
    check_quorum: bool = True
    max_inflight: int = 64  # appends in flight per follower (pipelining, thesis §10.2.2)
    max_entries_per_msg: int = 256  # batching
    max_bytes_per_msg: int = 1 << 20
    quiesce: bool = False  # an idle group goes quiet (needs the driver's `leader_alive`)


class RaftError(Exception):
    """Base for the refusals of a Raft node; the shell maps them onto `MapError`s."""


class NotLeader(RaftError):
    """A proposal or read reached a node that is not the leader.

    Args:
        leader: the leader this node knows of, or `NONE`; the caller retries there.
    """

    def __init__(self, leader: int) -> None:
        self.leader = leader
        hint = f"node {leader} is" if leader != NONE else "no leader is known; an election"
        super().__init__(f"not the leader: {hint} in progress, retry there")


class ProposalRefused(RaftError):
    """The leader refused a proposal (e.g. a configuration change is already pending)."""


class EntryKind(enum.Enum):
    """What a log entry carries."""

    NORMAL = 1
    CONF_CHANGE = 2  # data is the whole new `Config`, encoded
    NOOP = 3  # appended by a new leader (thesis §6.4: commit an entry of its own term)


@dataclass(frozen=True, slots=True)
class Entry:
    """One log entry: `index` is its position, `term` the leader's term that created it."""

    term: int
    index: int
    kind: EntryKind = EntryKind.NORMAL
    data: bytes = b""


class ConfChangeKind(enum.Enum):
    """A single-server membership change (thesis §4.1)."""

    ADD_VOTER = 1  # also promotes a learner
    ADD_LEARNER = 2
    REMOVE_NODE = 3


@dataclass(frozen=True, slots=True)
class ConfChange:
    """Add or remove one server; see `Config.apply`."""

    kind: ConfChangeKind
    node: int


@dataclass(frozen=True, slots=True)
class Config:
    """A group's members: voters elect and count for commit, learners only receive the log."""

    voters: frozenset[int] = frozenset()
    learners: frozenset[int] = frozenset()

    @property
    def members(self) -> frozenset[int]:
        """Every node that receives the log."""
        return self.voters | self.learners

    def quorum(self) -> int:
        """How many voters form a majority."""
        return len(self.voters) // 2 + 1

    def has_quorum(self, nodes: set[int] | frozenset[int]) -> bool:
        """Whether `nodes` contain a majority of the voters (learners never count)."""
        return len(self.voters & nodes) >= self.quorum()

    def apply(self, change: ConfChange) -> Config:
        """The configuration after one single-server change.

        Any majority of the old voters overlaps any majority of the new ones, which is what
        makes a change without joint consensus safe (thesis §4.1).

        Raises:
            ValueError: the change is a no-op, a demotion, or would leave no voter.
        """
        node = change.node
        if change.kind is ConfChangeKind.ADD_VOTER:
            if node in self.voters:
                raise ValueError(f"node {node} is already a voter")
            return Config(self.voters | {node}, self.learners - {node})
        if change.kind is ConfChangeKind.ADD_LEARNER:
            if node in self.members:
                raise ValueError(f"node {node} is already a member; demotion is not supported")
            return Config(self.voters, self.learners | {node})
        if node not in self.members:
            raise ValueError(f"node {node} is not a member")
        if self.voters == {node}:
            raise ValueError(f"node {node} is the last voter")
        return Config(self.voters - {node}, self.learners - {node})

    def encode(self) -> bytes:
        """Bytes for a CONF_CHANGE entry: `voters;learners`, comma-separated ids."""
        return ";".join(
            ",".join(map(str, sorted(s))) for s in (self.voters, self.learners)
        ).encode()

    @classmethod
    def decode(cls, data: bytes) -> Config:
        """The inverse of `encode`."""
        voters, learners = (
            frozenset(int(x) for x in part.split(",") if x) for part in data.decode().split(";")
        )
        return cls(voters, learners)


@dataclass(frozen=True, slots=True)
class Snapshot:
    """The applied state up to `index` (whose entry had `term`), with the config then."""

    index: int = 0
    term: int = 0
    config: Config = Config()
    data: bytes = b""


@dataclass(frozen=True, slots=True)
class HardState:
    """What must survive a crash besides the log (Raft paper Fig. 2: currentTerm, votedFor)."""

    term: int = 0
    vote: int = NONE
    commit: int = 0


@dataclass(frozen=True, slots=True)
class PersistentState:
    """What a node restarts from: everything persisted through `Ready`s (and `compact`)."""

    hard_state: HardState = HardState()
    snapshot: Snapshot = Snapshot()
    entries: tuple[Entry, ...] = ()

    @classmethod
    def bootstrap(cls, config: Config) -> PersistentState:
        """The identical initial state of every founding member: one committed config entry.

        A node that joins later starts from `PersistentState()` and receives this entry (or a
        snapshot) from the leader, so it learns the configuration history like any follower.
        """
        entry = Entry(1, 1, EntryKind.CONF_CHANGE, config.encode())
        return cls(HardState(term=1, commit=1), Snapshot(), (entry,))


class MessageKind(enum.Enum):
    """The RPCs of the Raft paper (Fig. 2), PreVote (thesis §9.6) and ReadIndex (§6.4)."""

    APP = 1
    APP_RESP = 2
    VOTE = 3
    VOTE_RESP = 4
    PRE_VOTE = 5
    PRE_VOTE_RESP = 6
    HEARTBEAT = 7
    HEARTBEAT_RESP = 8
    SNAP = 9
    READ_INDEX = 10
    READ_INDEX_RESP = 11
    QUIESCE = 12  # a heartbeat that also tells the follower to stop its election timer


@dataclass(frozen=True, slots=True)
class Message:
    """One message between two nodes of a group.

    `index`/`log_term` are the entry preceding `entries` (APP), the sender's last entry (VOTE,
    PRE_VOTE), the acknowledged or rejected index (APP_RESP) or the read index (READ_INDEX_RESP).
    A rejecting APP_RESP carries `reject_hint`/`log_term`: the follower's guess of the last
    entry both logs may share, so the leader skips a whole term per round trip.
    """

    kind: MessageKind
    sender: int
    to: int
    term: int
    log_term: int = 0
    index: int = 0
    entries: tuple[Entry, ...] = ()
    commit: int = 0
    reject: bool = False
    reject_hint: int = 0
    snapshot: Snapshot | None = None
    context: bytes = b""


class Role(enum.Enum):
    """A node's role in its current term."""

    FOLLOWER = 1
    PRE_CANDIDATE = 2
    CANDIDATE = 3
    LEADER = 4


@dataclass(frozen=True, slots=True)
class ReadState:
    """A linearizable read may be served once the state machine has applied `index`."""

    index: int
    context: bytes


@dataclass(frozen=True, slots=True)
class Ready:
    """Everything a node asks its driver to do, in this order (the order contract):

    1. persist `snapshot` (if any: a leader's, which replaces the whole stored log, entries
       after its index included, since they may belong to a branch that lost), then `entries`
       (the first one replaces every stored entry from its index on), then `hard_state` (if
       any); atomically or in that order, synced. (`RaftNode.compact` is the other kind: it
       drops only the entries it covers.);
    2. only then send `messages`: a vote or an acknowledgement promises what was persisted;
    3. apply `snapshot`, then `committed_entries`, in order; serve `read_states` once applied;
    4. call `RaftNode.advance(ready)` before asking for the next `Ready`.
    """

    hard_state: HardState | None = None
    entries: tuple[Entry, ...] = ()
    snapshot: Snapshot | None = None
    messages: tuple[Message, ...] = ()
    committed_entries: tuple[Entry, ...] = ()
    read_states: tuple[ReadState, ...] = ()
    role: Role = Role.FOLLOWER
    leader: int = NONE

    def empty(self) -> bool:
        """Whether there is nothing to persist, send or apply."""
        return not (
            self.hard_state
            or self.entries
            or self.snapshot
            or self.messages
            or self.committed_entries
            or self.read_states
        )
