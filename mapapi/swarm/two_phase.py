"""The coordinator of a transaction over several chunks, pure (DESIGN §13).

Two-phase commit across the chunks' Raft groups, as a state machine that knows
outcomes, not sockets: `LogCommits` (and the simulator) propose what it asks
and feed back how each entry was decided.

1. Prepare each chunk in `ChunkId` order, one after the other: a prepare that
   holds reserves its chunk (`swarm/apply_tx.py`), and taking chunks in one
   order means two transactions never wait for each other in a circle.
2. All prepared: decide commit, at the largest time they reserved, in the first
   chunk's log. A conflict, or a prepare whose fate is unknown:
   decide abort there instead (an unknown prepare may have landed).
3. The first chunk's log answers with the decision it keeps (a recovering peer
   may have aborted the transaction first); that decision goes to every other
   chunk that may hold a prepare. One that cannot be reached is left to
   recovery, which reads the same first chunk's log.

Only a commit decision commits, and only the coordinator proposes one, after
every chunk prepared: so a transaction whose commit decision the coordinator
never saw applied was aborted or is `uncertain`, never half applied.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass, field

from mapapi.core.change import Conflict
from mapapi.core.ids import ChunkId
from mapapi.core.proposal import LogEntry, Proposal, TxDecision


class Phase(enum.Enum):
    """Where a two-phase commit stands."""

    PREPARING = "preparing"
    DECIDING = "deciding"  # proposing the decision to the first chunk
    SPREADING = "spreading"  # proposing the first chunk's decision to the others
    DONE = "done"


@dataclass(frozen=True, slots=True)
class Answer:
    """How a chunk's log decided one entry the coordinator proposed (None fields:
    not this kind); `unknown` when the proposer could not learn it."""

    prepared: int = 0
    conflicts: tuple[Conflict, ...] = ()
    decision: TxDecision | None = None
    busy: str = ""
    unknown: str = ""


@dataclass
class TwoPhase:
    """One multi-chunk transaction's coordinator (see the module docstring).

    Args:
        prepares: each chunk's prepare; all share one commit id and name the
            same participants, in id order.
    """

    prepares: Mapping[ChunkId, Proposal]
    phase: Phase = Phase.PREPARING
    reserved: dict[ChunkId, int] = field(default_factory=dict)
    touched: list[ChunkId] = field(default_factory=list)  # may hold a prepare
    decision: TxDecision | None = None
    conflicts: tuple[Conflict, ...] = ()
    busy: str = ""
    failed: str = ""  # a prepare's fate was unknown: aborted, not committed
    uncertain: str = ""  # the first chunk's decision is unknown
    _waiting: set[ChunkId] = field(default_factory=set)

    def __post_init__(self) -> None:
        first = next(iter(self.prepares.values()))
        if list(self.prepares) != list(first.participants) or len(self.prepares) < 2:
            raise ValueError("a two-phase commit needs a prepare for each participant, in order")
        self.order = first.participants
        self.commit_id = first.commit_id

    def start(self) -> list[tuple[ChunkId, LogEntry]]:
        """The first entry to propose: the first chunk's prepare."""
        return self._prepare(0)

    def answered(self, chunk: ChunkId, answer: Answer) -> list[tuple[ChunkId, LogEntry]]:
        """Take in how `chunk` decided the entry proposed to it; returns what to
        propose next (several at once may go in parallel; none when done)."""
        if self.phase is Phase.PREPARING:
            return self._after_prepare(chunk, answer)
        if self.phase is Phase.DECIDING:
            return self._after_first_decision(answer)
        if self.phase is Phase.SPREADING:
            self._waiting.discard(chunk)
            if answer.unknown:
                self.uncertain = self.uncertain or answer.unknown
            if not self._waiting:
                self.phase = Phase.DONE
        return []

    @property
    def done(self) -> bool:
        """Whether nothing is left to propose."""
        return self.phase is Phase.DONE

    @property
    def committed(self) -> bool:
        """Whether the transaction's first chunk decided commit."""
        return self.decision is not None and self.decision.commit

    @property
    def aborted_why(self) -> str:
        """Why the transaction did not commit, in a few words ("" if it did or is open)."""
        if self.conflicts:
            return f"{len(self.conflicts)} conflict(s)"
        return self.busy or self.failed

    def _prepare(self, i: int) -> list[tuple[ChunkId, LogEntry]]:
        chunk = self.order[i]
        self.touched.append(chunk)
        return [(chunk, self.prepares[chunk])]

    def _after_prepare(self, chunk: ChunkId, answer: Answer) -> list[tuple[ChunkId, LogEntry]]:
        if answer.prepared:
            self.reserved[chunk] = answer.prepared
            i = self.order.index(chunk) + 1
            if i < len(self.order):
                return self._prepare(i)
            return self._decide(TxDecision(self.commit_id, True, max(self.reserved.values())))
        self.conflicts, self.busy = answer.conflicts, answer.busy
        if answer.decision is not None:  # recovery aborted it before this prepare landed
            self.failed = "a peer recovering it aborted the transaction while it prepared"
        if answer.unknown:
            self.failed = answer.unknown
        elif len(self.touched) == 1 and answer.decision is None:
            # The first chunk refused: nothing is prepared anywhere.
            self.decision = TxDecision(self.commit_id, False)
            self.phase = Phase.DONE
            return []
        return self._decide(TxDecision(self.commit_id, False))

    def _decide(self, decision: TxDecision) -> list[tuple[ChunkId, LogEntry]]:
        self.phase = Phase.DECIDING
        return [(self.order[0], decision)]

    def _after_first_decision(self, answer: Answer) -> list[tuple[ChunkId, LogEntry]]:
        if answer.decision is None:
            # The first chunk's log may or may not have taken the decision; recovery
            # settles the transaction from it.
            self.uncertain = answer.unknown or "the first chunk's decision is unknown"
            self.phase = Phase.DONE
            return []
        self.decision = answer.decision
        if not self.decision.commit and not self.aborted_why:
            self.failed = "a peer recovering it aborted the transaction before it committed"
        rest = [c for c in self.touched if c != self.order[0]]
        self._waiting = set(rest)
        self.phase = Phase.SPREADING if rest else Phase.DONE
        return [(c, answer.decision) for c in rest]
