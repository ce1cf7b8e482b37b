"""`Announcements`: soft-state entries a peer keeps alive in the Chord ring.

A peer announces things under ring keys (itself as a chunk's holder, a chunk's
box in the cells of the spatial index). Entries live for a time-to-live, so
the peer re-adds them every third of it; when what a thing should announce
changes (a new address, a grown box), the entries it no longer needs are
removed and the new ones added. Everything is best effort: an entry that
could not be removed expires by itself, one that could not be added is added
at the next refresh.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Awaitable, Callable, Hashable, Sequence
from typing import TYPE_CHECKING, Generic, TypeVar

from mapapi.core import limits
from mapapi.core.errors import MapError, UsageError
from mapapi.net.asking import ask_all

if TYPE_CHECKING:
    from mapapi.lookup.dht.chord import ChordNode

log = logging.getLogger(__name__)

K = TypeVar("K", bound=Hashable)

Entry = tuple[int, bytes]
"""A ring key and the member stored under it."""

_PARALLEL = 16  # requests in flight while announcing many entries


class Announcements(Generic[K]):
    """The entries of every registered thing, kept alive in one Chord node.

    Args:
        entries_of: the entries a thing should have in the ring now (called at
            each announcement, so they follow changes).
        ttl: seconds an entry lives unless refreshed.
        what: a word for log lines ("holder", "box").
        before_refresh: awaited before each periodic refresh (to recompute what
            is cheap to keep approximate between refreshes, off the event loop).
    """

    def __init__(
        self,
        entries_of: Callable[[K], Sequence[Entry]],
        ttl: float,
        what: str,
        *,
        before_refresh: Callable[[], Awaitable[None]] | None = None,
    ) -> None:
        limits.ttl(ttl)
        self.ttl = ttl
        self.chord: ChordNode | None = None
        self._entries_of = entries_of
        self._before_refresh = before_refresh
        self._what = what
        self._sent: dict[K, frozenset[Entry]] = {}  # registered thing -> entries in the ring
        self._lock = asyncio.Lock()  # one update at a time: no add after its remove
        self._refresher: asyncio.Task[None] | None = None

    def __contains__(self, thing: object) -> bool:
        return thing in self._sent

    def registered(self) -> list[K]:
        """The things announced now."""
        return list(self._sent)

    def start(self, chord: ChordNode, things: Sequence[K] = ()) -> None:
        """Announce `things` through `chord`, and refresh every announcement in the
        background until `close`."""
        if self._refresher is not None:
            raise UsageError(f"the {self._what} announcements are on already")
        self.chord = chord
        for thing in things:
            self._sent.setdefault(thing, frozenset())
        self._refresher = asyncio.get_running_loop().create_task(
            self._refresh_forever(), name=f"{self._what} refresh {chord.me.address}"
        )

    async def add(self, thing: K) -> None:
        """Announce `thing` and keep it alive; when it is announced already, send
        only what changed in its entries."""
        self._sent.setdefault(thing, frozenset())
        await self._announce(thing, renew=False)

    async def remove(self, thing: K) -> None:
        """Withdraw `thing`'s entries and stop refreshing them."""
        async with self._lock:
            sent = self._sent.pop(thing, frozenset())
            await self._send(frozenset(), sent, thing)

    async def refresh(self) -> None:
        """Announce every registered thing again: its time-to-live restarts."""
        if self._before_refresh is not None:
            await self._before_refresh()
        for thing in list(self._sent):
            await self._announce(thing, renew=True)

    async def _announce(self, thing: K, *, renew: bool) -> None:
        if self.chord is None:
            return
        async with self._lock:
            if thing not in self._sent:  # removed while we waited
                return
            try:
                wanted = frozenset(self._entries_of(thing))
            except MapError as exc:  # e.g. its chunk was dropped meanwhile
                log.warning("no %s entries for %s: %s", self._what, thing, exc)
                return
            sent = self._sent[thing]
            add = wanted if renew else wanted - sent
            if add or sent - wanted:
                ok = await self._send(add, sent - wanted, thing)
                self._sent[thing] = wanted if ok else sent
            # on a failure `sent` stays: its entries are removed at the next try

    async def _send(self, add: frozenset[Entry], drop: frozenset[Entry], thing: K) -> bool:
        """Add and remove entries; returns whether every request succeeded."""
        chord = self.chord
        if chord is None:
            return False
        gate = asyncio.Semaphore(_PARALLEL)

        async def one(entry: Entry, adding: bool) -> None:
            async with gate:
                if adding:
                    await chord.add(entry[0], entry[1], self.ttl)
                else:
                    await chord.remove(entry[0], entry[1])

        calls = {(e, False): one(e, False) for e in drop} | {(e, True): one(e, True) for e in add}
        answers = await ask_all(calls)
        if answers.failed:  # one line: the others likely failed the same way
            error = next(iter(answers.failed.values()))
            log.warning("could not announce %s %s: %s", self._what, thing, error)
        return not answers.failed

    async def _refresh_forever(self) -> None:
        while True:
            await self.refresh()
            await asyncio.sleep(self.ttl / 3)

    async def withdraw_all(self) -> None:
        """Stop refreshing and withdraw every entry (a graceful stop)."""
        await self.close()
        for thing in list(self._sent):
            await self.remove(thing)

    async def close(self) -> None:
        """Stop the refresh task (idempotent); the entries stay until they expire."""
        task, self._refresher = self._refresher, None
        if task is not None:
            task.cancel()
            await asyncio.gather(task, return_exceptions=True)
