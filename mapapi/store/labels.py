"""Labels: a secondary index of the store by what a row belongs to (a mission).

The core knows nothing of missions; the application does. It gives a store
its `Labels` at construction (DESIGN: hooks are passed in, never patched in):
per protobuf type, a function that reads a row's payload and says which set
the row belongs to (its label: a mission's name), what it weighs in that
set's size (1, or a point block's points) and its box. A store that keeps
labels (`LabelledStore`) indexes every revision of a labelled type under its
label, so a read of one mission's rows reads only them (at any time: the
index is per revision, and the read picks each item's newest revision at
that time as every read does), and keeps, per label and chunk, a summary of
the live rows now (how many, their weight, the box around them), brought up
to date by every commit applied, every replica installed and every replica
dropped, whichever path applied it.

`summarise` computes the same summaries from scratch: the answer for a store
that keeps no labels, and the oracle of the tests.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

from mapapi.core.history import Revision
from mapapi.core.ids import ChunkId

Box = tuple[float, float, float, float, float, float]
"""xmin, ymin, zmin, xmax, ymax, zmax (the store knows no `BBox`, which lies above it)."""


@dataclass(frozen=True, slots=True)
class RowLabel:
    """What one row says about the set it belongs to: the set's label (a
    mission's name), the row's weight in the set's size, and its box (None:
    the row has no place, as an edge)."""

    label: str
    weight: int = 1
    box: Box | None = None


LabelFn = Callable[[bytes], RowLabel | None]
"""A row's payload -> its label, or None when the row belongs to no set."""


@dataclass(frozen=True)
class Labels:
    """How an application labels rows: protobuf type name -> `LabelFn`.

    Args:
        by_type: the labelled types; rows of other types carry no label.
        version: changes when a function changes what it answers, so that a
            store labelled by the old functions is labelled again.
    """

    by_type: Mapping[str, LabelFn] = field(default_factory=dict)
    version: str = "1"

    @property
    def signature(self) -> str:
        """What a store records of the labels it keeps (version and types)."""
        return f"{self.version}:{','.join(sorted(self.by_type))}"

    def of(self, type_name: str) -> LabelFn | None:
        """The function labelling rows of `type_name`, or None."""
        return self.by_type.get(type_name)


@dataclass(frozen=True, slots=True)
class LabelSummary:
    """The live rows of one label in one chunk, now: how many, their summed
    weight and the box around those that have one."""

    label: str
    chunk: ChunkId
    table: str
    items: int
    weight: int
    box: Box | None


@runtime_checkable
class LabelledStore(Protocol):
    """What a store that keeps a label index adds to `ReplicaStore`
    (`mapapi.store.sqlite_labelled`)."""

    labels: Labels

    def scan_labelled(
        self, time: int, label: str, *, table: str | None = None, chunk: ChunkId | None = None
    ) -> list[Revision]:
        """The items labelled `label` visible at `time` (in a table or chunk), by id."""

    def label_chunks(self, label: str, table: str | None = None) -> list[ChunkId]:
        """The chunks that hold or held rows labelled `label` (of `table`)."""

    def label_summaries(self, labels: Sequence[str] | None = None) -> list[LabelSummary]:
        """The summary of every label (or of `labels`) per chunk, now: only
        sets with live rows, by label, table and chunk."""


def union(boxes: Iterable[Box | None]) -> Box | None:
    """The box around `boxes` (None among them ignored; None if none is left)."""
    found = [b for b in boxes if b is not None]
    if not found:
        return None
    lo = [min(b[k] for b in found) for k in range(3)]
    hi = [max(b[k] for b in found) for k in range(3, 6)]
    return (lo[0], lo[1], lo[2], hi[0], hi[1], hi[2])


@dataclass(slots=True)
class Tally:
    """A set's summary while it is counted: rows, weight, box."""

    items: int = 0
    weight: int = 0
    box: Box | None = None

    def add(self, row: RowLabel) -> None:
        """Count one more live row."""
        self.items += 1
        self.weight += row.weight
        self.box = union((self.box, row.box))


def summarise(
    revisions: Iterable[Revision], labels: Labels, types: Mapping[str, str]
) -> list[LabelSummary]:
    """The summaries of `revisions`, each an item's live revision now, computed
    from scratch (`types`: table -> type name).

    Returns:
        One summary per label and chunk, sorted as `label_summaries` sorts.
    """
    tallies: dict[tuple[str, ChunkId], Tally] = {}
    tables: dict[ChunkId, str] = {}
    for revision in revisions:
        fn = labels.of(types.get(revision.table, ""))
        row = None if fn is None or revision.removed else fn(revision.data)
        if row is None:
            continue
        tables[revision.chunk_id] = revision.table
        tallies.setdefault((row.label, revision.chunk_id), Tally()).add(row)
    found = [
        LabelSummary(label, chunk, tables[chunk], t.items, t.weight, t.box)
        for (label, chunk), t in tallies.items()
    ]
    return sorted(found, key=lambda s: (s.label, s.table, s.chunk))
