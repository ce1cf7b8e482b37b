"""Chunks and their holders: who holds what (DESIGN §7), and a table's name and type.

Plain frozen dataclasses, each mapping field by field onto the message of the
same name in `proto/mapapi/v1/wire.proto` (see `mapapi.net.messages`).
"""

from __future__ import annotations

from dataclasses import dataclass

from mapapi.core.ids import ChunkId, ItemId
from mapapi.net.messages.peers import Member


@dataclass(frozen=True, slots=True)
class TableInfo:
    """A table's name and full protobuf type name."""

    name: str
    type_name: str


@dataclass(frozen=True, slots=True)
class HoldersQuery:
    """Who holds `chunk`, or (chunk None) the chunk that holds `item`?"""

    chunk: ChunkId | None
    item: ItemId | None


@dataclass(frozen=True, slots=True)
class Holders:
    """The answer to `HoldersQuery`; empty when the asked peer does not know."""

    chunk: ChunkId | None
    table: str
    holders: tuple[Member, ...]


@dataclass(frozen=True, slots=True)
class ChunkListQuery:
    """Which chunks do you hold (of `table`, or of every table when empty)?"""

    table: str = ""


@dataclass(frozen=True, slots=True)
class ChunkSummary:
    """One chunk a peer holds: its id, table and number of live items."""

    chunk: ChunkId
    table: str
    items: int


@dataclass(frozen=True, slots=True)
class ChunkList:
    """The answer to `ChunkListQuery`."""

    chunks: tuple[ChunkSummary, ...]


BODIES: dict[str, type] = {
    "holders_query": HoldersQuery,
    "holders": Holders,
    "chunk_list_query": ChunkListQuery,
    "chunk_list": ChunkList,
}
"""Envelope body field -> class, for the messages of this area."""
