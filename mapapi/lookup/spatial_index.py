"""The spatial index over the Chord ring (DESIGN §7): chunks found by where
they lie.

The grid arithmetic is `mapapi.lookup.spatial`; this module stores and queries entries
in the ring. `register(box, entry)` adds the entry to every cell the box
overlaps (clamped to the index's bounds); `query(box)` asks the owner of every
overlapping cell for the entries whose own box overlaps the query box, with the
"bbox" filter evaluated there, so entries of far-away chunks that merely share
a cell never travel. An entry is a `mapapi.v1.SpatialEntry` serialized
deterministically: the chunk, its table, its box, the missions it holds and
the holder that announces it (each holder keeps its own entry alive).
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from google.protobuf.message import DecodeError

from mapapi._pb.mapapi.v1 import lookup_pb2, maps_pb2
from mapapi.core.errors import QueryError
from mapapi.core.ids import ChunkId, PeerId
from mapapi.lookup.spatial import BBox, SpatialGrid
from mapapi.net.asking import ask_all

if TYPE_CHECKING:
    from mapapi.lookup.dht.chord import ChordNode

log = logging.getLogger(__name__)

FILTER = "bbox"
"""The name of the server-side member filter every peer registers on its node."""

INDEX_NAME = "chunks"
"""The one spatial index of a swarm: chunks (and the missions they hold) by box."""

_PARALLEL = 32  # cells asked at once by one query
_MAX_MISSIONS = 64  # mission names an entry carries; a chunk of more is still found


Holder = tuple[PeerId, str]
"""A holder as the index lists it: its id and address."""


@dataclass(frozen=True, slots=True)
class SpatialRef:
    """A chunk in the spatial index: what it is, where it lies, who holds it."""

    chunk: ChunkId
    table: str
    bbox: BBox
    missions: tuple[str, ...] = ()
    holders: tuple[Holder, ...] = ()

    def encode(self) -> bytes:
        """The entry one holder stores in the ring (equal refs give equal bytes).

        Raises:
            ValueError: the ref does not name exactly one holder.
        """
        if len(self.holders) != 1:
            raise ValueError(f"an entry names one holder, this ref {len(self.holders)}")
        ((holder, address),) = self.holders
        entry = lookup_pb2.SpatialEntry(
            chunk=self.chunk.to_bytes(),
            table=self.table,
            bbox=box3(self.bbox),
            missions=sorted(self.missions)[:_MAX_MISSIONS],
            holder=holder.to_bytes(),
            address=address,
        )
        return bytes(entry.SerializeToString(deterministic=True))

    @classmethod
    def decode(cls, raw: bytes) -> SpatialRef:
        """The ref `encode` wrote.

        Raises:
            ValueError: not a spatial entry (bad bytes, id or box).
        """
        entry = lookup_pb2.SpatialEntry()
        try:
            entry.ParseFromString(raw)
        except DecodeError as exc:
            raise ValueError(f"not a spatial entry: {exc}") from exc
        if len(entry.chunk) != 16 or len(entry.holder) != 16 or not entry.HasField("bbox"):
            raise ValueError("a spatial entry needs 16-byte chunk and holder ids and a box")
        box = box_of(entry.bbox)
        holder = (PeerId.from_bytes(entry.holder), entry.address)
        chunk = ChunkId.from_bytes(entry.chunk)
        return cls(chunk, entry.table, box, tuple(entry.missions), (holder,))


def box3(box: BBox) -> maps_pb2.Box3:
    """`box` as a `mapapi.v1.Box3` message."""
    return maps_pb2.Box3(
        xmin=box.xmin, ymin=box.ymin, zmin=box.zmin, xmax=box.xmax, ymax=box.ymax, zmax=box.zmax
    )


def box_of(message: maps_pb2.Box3) -> BBox:
    """The box of a `mapapi.v1.Box3` message.

    Raises:
        InvalidBBox: a malformed box (it is a ValueError).
    """
    b = message
    return BBox(b.xmin, b.ymin, b.zmin, b.xmax, b.ymax, b.zmax)


def encode_filter(box: BBox, table: str | None = None) -> bytes:
    """The argument of the "bbox" filter."""
    spec = lookup_pb2.SpatialFilter(bbox=box3(box), table=table or "")
    return bytes(spec.SerializeToString(deterministic=True))


def decode_filter(argument: bytes) -> tuple[BBox, str | None]:
    """The box and table (None: any) of a filter argument `encode_filter` wrote;
    every member filter that takes a `mapapi.v1.SpatialFilter` parses it here.

    Raises:
        ValueError: the argument is no spatial filter, has no box, or a
            malformed one (`InvalidBBox` is a ValueError).
    """
    spec = lookup_pb2.SpatialFilter()
    try:
        spec.ParseFromString(argument)
    except DecodeError as exc:
        raise ValueError(f"not a spatial filter: {exc}") from exc
    if not spec.HasField("bbox"):
        raise ValueError("a spatial filter needs a box")
    return box_of(spec.bbox), spec.table or None


def bbox_filter(argument: bytes) -> Callable[[bytes], bool]:
    """The "bbox" member filter (`ChordNode.register_filter`): keep the entries
    whose box overlaps the filter's box (and of its table, when it names one).
    Members that are not spatial entries are dropped.

    Raises:
        ValueError: the argument is no valid filter.
    """
    box, table = decode_filter(argument)

    def keep(member: bytes) -> bool:
        try:
            ref = SpatialRef.decode(member)
        except ValueError:
            return False
        return ref.bbox.overlaps(box) and (not table or ref.table == table)

    return keep


@dataclass
class QueryStats:
    """What one query cost: cells asked (one Chord lookup and one get each),
    requests sent, and entries that travelled back."""

    cells: int = 0
    requests: int = 0
    transferred: int = 0
    failed_cells: list[int] = field(default_factory=list)


class SpatialIndex:
    """Register and query boxes in the ring of `chord` (registers the "bbox" filter).

    Args:
        chord: this peer's node.
        grid: the index geometry, equal on every peer (checked when joining).
        name: the index's name, part of every cell key.
    """

    def __init__(self, chord: ChordNode, grid: SpatialGrid, name: str = INDEX_NAME) -> None:
        self.chord = chord
        self.grid = grid
        self.name = name
        chord.register_filter(FILTER, bbox_filter)

    def cell_keys(self, box: BBox) -> list[int]:
        """The ring keys of the cells `box` overlaps (none when it lies outside)."""
        return [self.grid.cell_key(i, self.name) for i in self.grid.cells_overlapping(box)]

    def entries(self, ref: SpatialRef) -> list[tuple[int, bytes]]:
        """``(cell key, member)`` for each cell `ref`'s box overlaps (`ref` names
        the one holder that announces it)."""
        member = ref.encode()
        return [(key, member) for key in self.cell_keys(ref.bbox)]

    async def register(self, ref: SpatialRef, ttl: float) -> None:
        """Add `ref` to every cell its box overlaps, for `ttl` seconds (a peer keeps
        its chunks' refs alive with `mapapi.lookup.dht.announce.Announcements`).

        Raises:
            NetworkError: a cell's owner could not be reached.
        """
        gate = asyncio.Semaphore(_PARALLEL)

        async def one(key: int, member: bytes) -> None:
            async with gate:
                await self.chord.add(key, member, ttl)

        await asyncio.gather(*(one(k, m) for k, m in self.entries(ref)))

    async def query(
        self,
        box: BBox,
        table: str | None = None,
        *,
        exact_at_owner: bool = True,
        stats: QueryStats | None = None,
    ) -> list[SpatialRef]:
        """The refs whose box overlaps `box` (of `table`, if given), one per chunk,
        sorted by chunk id. A box partly outside the bounds is clamped; one
        fully outside matches nothing.

        Args:
            exact_at_owner: filter at each cell's owner (the default); without it
                every entry of the cells travels and is filtered here (the
                paper's Fig. 8 compares the two).
            stats: filled with what the query cost.

        Raises:
            QueryError: no cell owner answered at all (entries in cells that
                could not be reached are missing otherwise, logged and counted
                in `stats.failed_cells`).
        """
        argument = encode_filter(box, table)
        keep = bbox_filter(argument)
        found: dict[ChunkId, SpatialRef] = {}
        filter, sent = (FILTER, argument) if exact_at_owner else ("", b"")
        for member in await self.members(box, filter, sent, stats):
            if keep(member):
                ref = SpatialRef.decode(member)
                found[ref.chunk] = _merge(found.get(ref.chunk), ref)
        return [found[c] for c in sorted(found)]

    async def members(
        self,
        box: BBox,
        filter: str = "",
        argument: bytes = b"",
        stats: QueryStats | None = None,
    ) -> list[bytes]:
        """Every member of every cell `box` overlaps, as each cell's owner's
        `filter` keeps them for `argument` (a member in several cells comes
        once per cell).

        Raises:
            QueryError: no cell owner answered at all (members of cells that
                could not be reached are missing otherwise, logged and counted
                in `stats.failed_cells`).
        """
        stats = stats if stats is not None else QueryStats()
        cells = self.grid.cells_overlapping(box)
        stats.cells = len(cells)
        gate = asyncio.Semaphore(_PARALLEL)

        async def ask(cell: int) -> set[bytes]:
            async with gate:
                return await self.chord.get(self.grid.cell_key(cell, self.name), filter, argument)

        before = self.chord.requests_sent
        answers = await ask_all({c: ask(c) for c in cells})
        stats.requests += self.chord.requests_sent - before
        for cell, error in answers.failed.items():
            log.warning("cell %d of index %r did not answer: %s", cell, self.name, error)
            stats.failed_cells.append(cell)
        members: list[bytes] = []
        for answer in answers.ok.values():
            stats.transferred += len(answer)
            members.extend(answer)
        if cells and len(stats.failed_cells) == len(cells):
            raise QueryError(f"no owner of the {len(cells)} cells of {box} answered")
        return members


def _merge(old: SpatialRef | None, new: SpatialRef) -> SpatialRef:
    """One ref per chunk, listing every holder: holders may have announced boxes
    of different moments (a grown box before the old entry expired); keep their
    union. A holder that moved may briefly have two addresses listed: one is kept."""
    if old is None:
        return new
    holders = dict(old.holders) | dict(new.holders)
    return SpatialRef(
        new.chunk,
        new.table,
        old.bbox.union(new.bbox),
        tuple(sorted(set(old.missions) | set(new.missions))),
        tuple(sorted(holders.items())),
    )
