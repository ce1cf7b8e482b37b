"""`ChunkPlaces`: where this peer's chunks lie, announced in the spatial index.

A chunk of a table whose items have a box (`mapapi.lookup.extent`) lies in the box
around its live items. Every holder announces that box in the index's cells
(DESIGN §7) and keeps its own entry alive. The box is cached per chunk and
grown as commits insert items; a commit that moves or removes items may shrink
it, which the next periodic refresh computes exactly (until then a query may
still list the chunk for the region it just left: a superset, never a miss).

Computing a box reads and decodes every live item of the chunk: seconds for a
chunk of 100,000 rows. A store that keeps the application's label summaries
(the map tables': `mapapi.store.labels`) has the box already, per label and
chunk, and it is taken from there (see `_summarised`). Either way `warm`
computes the missing boxes in a worker thread (`mapapi.store.offload`) before
they are announced or queried, so the event loop keeps serving (issue 14 §1);
commits applied meanwhile are kept aside and grow the box computed, so it still
holds every item (a box computed from a replica that was replaced or dropped
meanwhile is thrown away).
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable, Iterable, Sequence
from dataclasses import replace
from typing import TYPE_CHECKING

from google.protobuf.message import DecodeError

from mapapi.core.errors import ChunkNotFound
from mapapi.core.history import Revision
from mapapi.core.ids import ChunkId
from mapapi.core.table import message_class
from mapapi.lookup.dht.announce import Announcements, Entry
from mapapi.lookup.extent import extent_of
from mapapi.lookup.spatial import BBox
from mapapi.lookup.spatial_index import Holder, SpatialIndex, SpatialRef
from mapapi.store.base import ReplicaStore
from mapapi.store.labels import LabelledStore, LabelSummary
from mapapi.store.offload import off_loop

if TYPE_CHECKING:
    from mapapi.lookup.dht.chord import ChordNode

log = logging.getLogger(__name__)


class ChunkPlaces:
    """The boxes of the chunks one peer holds, and their announcements.

    Off the network it only computes boxes; `start` makes it announce them.
    """

    def __init__(self, store: ReplicaStore) -> None:
        self.store = store
        self.index: SpatialIndex | None = None
        self.announced: Announcements[ChunkId] | None = None
        self._me: Callable[[], Holder] | None = None
        self._refs: dict[ChunkId, SpatialRef | None] = {}  # cached; None: no box
        self._loose: set[ChunkId] = set()  # cached box may be larger than exact
        self._computing: dict[ChunkId, list[Revision]] = {}  # -> revisions applied meanwhile
        self._warming = asyncio.Lock()  # one `warm` at a time

    # -- boxes -----------------------------------------------------------------------
    def _placed_type(self, table: str) -> str | None:
        return _placed_type(self.store, table)

    def ref(self, chunk: ChunkId) -> SpatialRef | None:
        """Where `chunk` lies now, or None when it has no placed item.

        Raises:
            ChunkNotFound: the chunk is not held here.
        """
        if chunk not in self._refs:
            self._refs[chunk] = self._compute(chunk)
            self._loose.discard(chunk)
        return self._refs[chunk]

    def _compute(self, chunk: ChunkId) -> SpatialRef | None:
        return _compute(self.store, chunk, _summaries(self.store))

    async def warm(self, chunks: Iterable[ChunkId]) -> None:
        """Compute the boxes of `chunks` that are not cached, in a worker thread
        (see the module docstring); chunks not held here are skipped."""
        async with self._warming:
            missing = sorted({c for c in chunks if c not in self._refs})
            if not missing:
                return
            for chunk in missing:
                self._computing[chunk] = []
            try:
                computed = await off_loop(self.store, _compute_all, self.store, missing)
            finally:
                late = {c: self._computing.pop(c, None) for c in missing}
            for chunk, ref in computed.items():
                applied = late[chunk]
                if chunk in self._refs or applied is None:
                    continue  # computed meanwhile, or forgotten (replaced, dropped)
                self._refs[chunk] = ref
                self._loose.discard(chunk)
                if applied:
                    self.applied(applied)

    def caches(self, chunks: Iterable[ChunkId]) -> bool:
        """Whether the box of any of `chunks` is cached or being computed (and
        `applied` must see their commits)."""
        return any(c in self._refs or c in self._computing for c in chunks)

    def applied(self, revisions: Iterable[Revision]) -> None:
        """Account for a commit applied here (cached boxes grow; moves and
        removals leave them loose until the next refresh)."""
        by_chunk: dict[ChunkId, list[Revision]] = {}
        for revision in revisions:
            by_chunk.setdefault(revision.chunk_id, []).append(revision)
        for chunk, revs in by_chunk.items():
            if chunk in self._computing:
                self._computing[chunk] += revs  # grows the box once computed
            if chunk not in self._refs:
                continue  # computed in full when first needed
            type_name = self._placed_type(revs[0].table)
            if type_name is None:
                continue
            if any(r.kind != "inserted" for r in revs):
                self._loose.add(chunk)
            self._refs[chunk] = _grow(self._refs[chunk], chunk, revs[0].table, type_name, revs)

    def forget(self, chunk: ChunkId) -> None:
        """Drop the cached box of a chunk no longer held (or replaced wholesale)."""
        self._refs.pop(chunk, None)
        self._loose.discard(chunk)
        self._computing.pop(chunk, None)

    async def _tighten(self) -> None:
        """Recompute exactly the boxes that moves and removals may have shrunk,
        and compute those not known yet, of every chunk announced (off the loop)."""
        for chunk in sorted(self._loose):
            self.forget(chunk)
        if self.announced is not None:
            await self.warm(self.announced.registered())

    async def placed(self) -> list[SpatialRef]:
        """Every chunk held here that has a box (for queries off the network)."""
        held = self.store.chunk_ids()
        await self.warm(held)
        refs = []
        for chunk in held:
            try:
                ref = self.ref(chunk)
            except ChunkNotFound:
                continue  # dropped meanwhile
            if ref is not None:
                refs.append(ref)
        return refs

    # -- announcements -----------------------------------------------------------------
    def start(
        self, chord: ChordNode, index: SpatialIndex, ttl: float, me: Callable[[], Holder]
    ) -> None:
        """Announce the box of every chunk held here in `index`, each for `ttl`
        seconds, as held by `me()` (this peer's id and current address), and keep
        them alive (refreshed every third of it; boxes are computed off the loop)."""
        self.index = index
        self._me = me
        self.announced = Announcements(self._entries, ttl, "box", before_refresh=self._tighten)
        self.announced.start(chord, self.store.chunk_ids())

    def _entries(self, chunk: ChunkId) -> list[Entry]:
        try:
            ref = self.ref(chunk)
        except ChunkNotFound:
            return []  # dropped meanwhile: withdraw what was announced
        if ref is None or self.index is None or self._me is None:
            return []
        return self.index.entries(replace(ref, holders=(self._me(),)))

    async def update(self, chunks: Iterable[ChunkId]) -> None:
        """Announce the boxes of `chunks` (held here) where they changed, now (on
        the network; the first announcement of a chunk computes its box)."""
        if self.announced is not None:
            chunks = list(chunks)
            await self.warm(chunks)
            for chunk in chunks:
                await self.announced.add(chunk)

    async def withdraw(self, chunk: ChunkId) -> None:
        """Stop announcing a chunk this peer left."""
        if self.announced is not None:
            await self.announced.remove(chunk)
        self.forget(chunk)

    async def withdraw_all(self) -> None:
        """Withdraw every announcement (a graceful stop)."""
        if self.announced is not None:
            await self.announced.withdraw_all()

    async def close(self) -> None:
        """Stop refreshing (announcements expire by themselves) and go off the network."""
        if self.announced is not None:
            await self.announced.close()
        self.announced = self.index = None


def _placed_type(store: ReplicaStore, table: str) -> str | None:
    """The type name of `table` if its items have a place, else None."""
    type_name = store.tables().get(table)
    return type_name if type_name is not None and extent_of(type_name) else None


def _compute(
    store: ReplicaStore, chunk: ChunkId, summaries: dict[ChunkId, list[LabelSummary]] | None = None
) -> SpatialRef | None:
    """Where `chunk` lies now, from its live items (any thread): from the store's
    `summaries` of the chunk's labels when the store labels its rows (see
    `_summarised`), else by reading and decoding every live item.

    Raises:
        ChunkNotFound: the chunk is not held here.
    """
    table = store.chunk_table(chunk)
    type_name = _placed_type(store, table)
    if type_name is None:
        return None
    if summaries is not None and _summarised(store, type_name):
        return _from_summaries(chunk, table, summaries.get(chunk, []))
    revisions = store.scan(store.clock(), table=table, chunk=chunk)
    return _grow(None, chunk, table, type_name, revisions)


def _compute_all(
    store: ReplicaStore, chunks: Sequence[ChunkId]
) -> dict[ChunkId, SpatialRef | None]:
    """`_compute` of each of `chunks` held here (in a worker thread: see `warm`)."""
    summaries = _summaries(store)
    found: dict[ChunkId, SpatialRef | None] = {}
    for chunk in chunks:
        try:
            found[chunk] = _compute(store, chunk, summaries)
        except ChunkNotFound:
            continue
    return found


def _summaries(store: ReplicaStore) -> dict[ChunkId, list[LabelSummary]] | None:
    """The store's label summaries by chunk (None: it keeps none)."""
    if not isinstance(store, LabelledStore):
        return None
    found: dict[ChunkId, list[LabelSummary]] = {}
    for summary in store.label_summaries():
        found.setdefault(summary.chunk, []).append(summary)
    return found


def _summarised(store: ReplicaStore, type_name: str) -> bool:
    """Whether the store's label summaries place rows of `type_name`: it labels
    them. The application's labels put a row where its extent does, and name the
    mission its extent names (`mapapi.maps.labels`, `mapapi.lookup.extent`; a
    test compares the two), so a chunk's box is the box around its labels' boxes,
    kept by the store at every commit, and no item need be read."""
    return isinstance(store, LabelledStore) and store.labels.of(type_name) is not None


def _from_summaries(
    chunk: ChunkId, table: str, summaries: Sequence[LabelSummary]
) -> SpatialRef | None:
    placed = [s for s in summaries if s.box is not None]
    if not placed:
        return None
    box = BBox.enclosing(BBox.from_tuple(s.box) for s in placed if s.box is not None)
    missions = tuple(sorted({s.label for s in placed if s.label}))
    return SpatialRef(chunk, table, box, missions)


def _grow(
    ref: SpatialRef | None,
    chunk: ChunkId,
    table: str,
    type_name: str,
    revisions: Iterable[Revision],
) -> SpatialRef | None:
    """`ref` grown by the live items among `revisions` (a new ref if it was None)."""
    extent = extent_of(type_name)
    if extent is None:
        return ref
    cls = message_class(type_name)
    boxes: list[BBox] = [] if ref is None else [ref.bbox]
    missions = set() if ref is None else set(ref.missions)
    for revision in revisions:
        if revision.removed:
            continue
        try:
            message = cls.FromString(revision.data)
            box = extent.box(message)
        except (DecodeError, ValueError) as exc:  # a damaged item is not placed
            log.warning("item %s has no usable box: %s", revision.item_id, exc)
            continue
        if box is None:
            continue
        boxes.append(box)
        label = extent.label(message) if extent.label is not None else ""
        if label:  # a row that names no mission belongs to none
            missions.add(label)
    if not boxes:
        return None
    return SpatialRef(chunk, table, BBox.enclosing(boxes), tuple(sorted(missions)))
