"""Settling multi-chunk transactions whose coordinator went away (DESIGN §13).

A prepare holds its chunk until the transaction's decision reaches the chunk's
log. If the coordinator died, was cut off or gave up, the decision may never
come; so each chunk's leader watches the transactions prepared on the chunks it
leads, and once one has waited `after` seconds it settles it from the logs, not
from anyone's memory:

1. it proposes "abort" to the transaction's first chunk, whose log keeps the
   first decision it applies (`swarm/apply_tx.py`): the answer is the
   transaction's decision, abort or the commit the coordinator got there first;
2. it proposes that decision to its own chunk.

A transaction is thus never left in doubt while a majority of its first chunk's
voters and of this chunk's voters are reachable, and no peer's guess can
contradict the coordinator: both read the same log.
"""

from __future__ import annotations

import asyncio
import logging

from mapapi.core import codec
from mapapi.core.errors import MapError
from mapapi.core.ids import ChunkId, CommitId
from mapapi.core.proposal import Proposal, TxDecision
from mapapi.store.base import TxRow
from mapapi.store.offload import off_loop
from mapapi.swarm.log_commit import LogCommits

log = logging.getLogger(__name__)

RECOVER_AFTER = 15.0
"""Seconds a prepare may wait for its decision before a leader settles it: past
what a live coordinator needs (its prepares wait at most `PROPOSE_TIMEOUT` each
for a busy chunk or an election)."""
SWEEP_EVERY = 1.0
"""Seconds between two looks at the prepared transactions."""


class TxRecovery:
    """Settles abandoned multi-chunk transactions on the chunks this peer leads.

    Args:
        commits: proposes entries to any chunk's log (through its leader).
        after: seconds a prepare waits, as this leader saw it, before it is settled.
    """

    def __init__(self, commits: LogCommits, after: float = RECOVER_AFTER) -> None:
        self.commits = commits
        self.after = after
        self._seen: dict[tuple[ChunkId, CommitId], float] = {}
        self._task: asyncio.Task[None] | None = None
        self.settled = 0  # transactions this peer settled

    def start(self, every: float = SWEEP_EVERY) -> None:
        """Look at the prepared transactions every `every` seconds."""
        self._task = asyncio.get_running_loop().create_task(self._sweeps(every))

    async def close(self) -> None:
        """Stop looking."""
        if self._task is not None:
            self._task.cancel()
            await asyncio.gather(self._task, return_exceptions=True)
            self._task = None

    async def _sweeps(self, every: float) -> None:
        while True:
            await asyncio.sleep(every)
            await self.sweep()

    async def sweep(self) -> None:
        """Settle every transaction prepared on a chunk this peer leads that has
        waited `after` seconds since this peer first saw it."""
        now = asyncio.get_running_loop().time()
        store = self.commits.groups.store
        led = self.commits.groups.led()

        def prepared() -> dict[tuple[ChunkId, CommitId], TxRow]:
            return {(c, cid): row for c in led for cid, row in store.raft_tx_prepared(c)}

        # in a worker: a read per led chunk on the loop would wait for the interpreter
        # lock after each one while another thread computes (see `GroupMembers.reap`)
        waiting = await off_loop(store, prepared)
        self._seen = {key: self._seen.get(key, now) for key in waiting}
        for (chunk, cid), row in waiting.items():
            if now - self._seen[(chunk, cid)] < self.after:
                continue
            try:
                decision = await self.settle(chunk, cid, row)
            except MapError as exc:  # the next sweep tries again
                log.warning(
                    "transaction %s on chunk %s not settled yet: %s", cid.short, chunk.short, exc
                )
                continue
            self.settled += 1
            log.warning(
                "transaction %s on chunk %s was abandoned by its coordinator: settled as %s",
                cid.short,
                chunk.short,
                "committed" if decision.commit else "aborted",
            )

    async def settle(self, chunk: ChunkId, commit_id: CommitId, row: TxRow) -> TxDecision:
        """Decide a prepared transaction on `chunk` as its first chunk's log does
        (see the module docstring); returns that decision.

        Raises:
            MapError: a log could not be reached; nothing is decided here.
        """
        prepare = codec.decode_entry(row.data)
        assert isinstance(prepare, Proposal)  # apply_tx keeps the prepare
        first = prepare.participants[0]
        answer = await self.commits.propose(first, TxDecision(commit_id, False))
        assert answer.decision is not None  # apply_decision answers with the one it keeps
        if chunk != first:
            await self.commits.propose(chunk, answer.decision)
        return answer.decision
