"""What a transaction changes, and what a conflict is (DESIGN §5): pure values.

A `Change` is one buffered write to one item; a `Conflict` names an item someone
else changed after a transaction's begin time, with the base, ours and theirs;
a `MergeFn` is a table's policy for merging ours and theirs.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum

from mapapi.core.history import Revision
from mapapi.core.ids import ChunkId, ItemId


class Op(Enum):
    """What a buffered change does to its item."""

    INSERT = 1
    UPDATE = 2
    REMOVE = 3


@dataclass(frozen=True, slots=True)
class Change:
    """One buffered change; `data` is the serialized payload (empty for REMOVE)."""

    op: Op
    table: str
    item_id: ItemId
    chunk_id: ChunkId
    data: bytes = b""


@dataclass(frozen=True, slots=True)
class Conflict:
    """An item someone else changed after our begin time.

    Attributes:
        base: the item at our begin time (None if it did not exist).
        ours: our change (None when only read, under serializable isolation).
        theirs: the newest revision, written by the other side.
    """

    table: str
    item_id: ItemId
    chunk_id: ChunkId
    base: Revision | None
    ours: Change | None
    theirs: Revision


# Given our change, their newest revision and the base, return the merged
# payload, or None when the table's policy cannot merge them.
MergeFn = Callable[[Change, Revision, Revision | None], bytes | None]
