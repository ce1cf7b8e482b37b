"""A chunk leader's items in flight: written by proposals it appended to the
chunk's log and has not applied yet (issue 13 §3: the leader validates against
its state plus the entries not yet applied).

A proposal that writes or read an item in flight waits until the entry ahead
applies, and is then checked against the replica (`apply.early_conflicts`). When
the entry ahead committed, the newcomer's conflict is known without a round of
the log; when it failed, the newcomer goes on. Waiting, rather than refusing the
newcomer at once, keeps every conflict exact: an entry not yet applied may still
fail (a conflict of its own, a leader change), and a conflict must name a commit
that happened. The holders' decision at apply stays the authority
(`swarm/apply.py`); this only spares the losers of a race their rounds of the log,
which under contention were most rounds (`mapctl bench viewtest`).
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Collection, Iterator

from mapapi.core.ids import ChunkId, ItemId
from mapapi.core.proposal import LogEntry, Proposal
from mapapi.swarm.apply import Outcome, early_conflicts
from mapapi.swarm.groups import PROPOSE_TIMEOUT, RaftGroups


def items_of(entry: LogEntry) -> tuple[frozenset[ItemId], frozenset[ItemId]]:
    """What `entry` writes, and what it writes or read: the items a leader holds
    in flight for it, and those it waits for before checking it. Empty for
    entries the replica does not check early (prepares, decisions, time floors)."""
    if not isinstance(entry, Proposal) or entry.is_prepare:
        return frozenset(), frozenset()
    written = frozenset(c.item_id for c in entry.changes)
    return written, written | entry.read_set


class InFlight:
    """The items of the proposals this leader has appended and not yet applied."""

    def __init__(self) -> None:
        self._items: dict[tuple[ChunkId, ItemId], asyncio.Event] = {}

    def __len__(self) -> int:
        return len(self._items)

    async def propose(
        self, groups: RaftGroups, chunk: ChunkId, entry: LogEntry, data: bytes, *, heavy: bool
    ) -> Outcome:
        """Propose `entry` (encoded: `data`) as the chunk's leader; how the holders
        decided it. First, once the entries in flight on its items applied, answer
        the conflicts this replica shows already: every holder would decide so, and
        the loser learns it without a round of the log. A heavy entry (a mission's
        rows) goes straight to the log: checking it here would hold the loop."""
        written, touched = items_of(entry) if not heavy else (frozenset(), frozenset())
        if touched:
            await self.clear_of(chunk, touched, PROPOSE_TIMEOUT)
            if conflicts := early_conflicts(groups.store, chunk, entry):
                return Outcome(conflicts=conflicts)
        with self.holding(chunk, written):
            applied = (await groups.propose(chunk, data)).result
        assert isinstance(applied, Outcome)  # the groups apply with `apply_tx.applier`
        return applied

    async def clear_of(self, chunk: ChunkId, items: Collection[ItemId], timeout: float) -> None:  # noqa: ASYNC109
        """Wait until no entry in flight here writes any of `items` of `chunk`; after
        `timeout`, stop waiting (the log then decides, as it always may)."""
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(timeout):
                while ahead := next(self._ahead(chunk, items), None):
                    await ahead.wait()

    def _ahead(self, chunk: ChunkId, items: Collection[ItemId]) -> Iterator[asyncio.Event]:
        if not self._items:
            return
        for item in items:
            event = self._items.get((chunk, item))
            if event is not None:
                yield event

    @contextlib.contextmanager
    def holding(self, chunk: ChunkId, items: Collection[ItemId]) -> Iterator[None]:
        """Hold `items` of `chunk` in flight for the body (the proposal's round of
        the log); then wake whoever waits for them, however the round ended."""
        done = asyncio.Event()
        keys = [(chunk, item) for item in items if (chunk, item) not in self._items]
        self._items.update(dict.fromkeys(keys, done))
        try:
            yield
        finally:
            for key in keys:
                del self._items[key]
            done.set()
