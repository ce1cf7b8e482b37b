"""Chunks found by place (DESIGN §7): `PlacedChunk`, and the query by bounding box
that answers with each chunk's holders, named as this peer knows them.

On the network the spatial index is asked (chunks held here are added even
before their announcement lands); alone, only the chunks held here are searched.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from mapapi.lookup.spatial_index import SpatialRef
from mapapi.net.messages import Member

if TYPE_CHECKING:
    from mapapi.core.ids import ChunkId, PeerId
    from mapapi.lookup.chunk_places import ChunkPlaces
    from mapapi.lookup.spatial import BBox, SpatialGrid
    from mapapi.lookup.spatial_index import QueryStats
    from mapapi.store.base import ReplicaStore
    from mapapi.swarm.node import Swarm


@dataclass(frozen=True, slots=True)
class PlacedChunk:
    """A chunk a spatial query found: where it lies, who holds it, and whether
    this peer does."""

    ref: SpatialRef
    holders: tuple[Member, ...]
    held: bool


@dataclass(frozen=True, slots=True)
class Here:
    """What a query knows of the peer asking: its id, name, replicas and swarm."""

    id: PeerId
    name: str
    store: ReplicaStore
    places: ChunkPlaces
    grid: SpatialGrid
    swarm: Swarm | None


async def query_bbox(
    here: Here, box: BBox, table: str | None = None, stats: QueryStats | None = None
) -> list[PlacedChunk]:
    """The chunks whose box overlaps `box` (of `table`, if given), with their
    holders, sorted by chunk id (see `mapapi.Peer.query_bbox`).

    Raises:
        QueryError: no owner of the box's cells answered.
    """
    if here.grid.clamp(box) is None:
        return []
    found: dict[ChunkId, SpatialRef] = {}
    if here.swarm is not None and here.swarm.index is not None:
        for ref in await here.swarm.index.query(box, table, stats=stats):
            found[ref.chunk] = ref
    for ref in await here.places.placed():  # what is held here is current
        inside = here.grid.clamp(ref.bbox) is not None  # as the index would have it
        if inside and ref.bbox.overlaps(box) and table in (None, ref.table):
            found[ref.chunk] = ref
    held = set(here.store.chunk_ids())
    return [_holders_of(here, found[c], c in held) for c in sorted(found)]


def _holders_of(here: Here, ref: SpatialRef, held: bool) -> PlacedChunk:
    if held:
        ids = here.store.holders(ref.chunk) or [here.id]
        return PlacedChunk(ref, tuple(_member(here, p) for p in ids), held=True)
    return PlacedChunk(ref, tuple(_member(here, p, a) for p, a in ref.holders), held=False)


def _member(here: Here, peer: PeerId, address: str | None = None) -> Member:
    """`peer` with its name when this peer knows it; `address` (where the
    spatial index says it serves the chunk) replaces the member list's."""
    swarm = here.swarm
    if peer == here.id:
        address_here = swarm.address if swarm is not None else ""
        return Member(here.id, address_here if address is None else address, here.name)
    known = swarm.members.get(peer) if swarm is not None else None
    if known is None:
        return Member(peer, address or "")
    return known if address is None else Member(peer, address, known.name)
