"""Revisions, multi-version item history and commit records (pure: no I/O).

A read at time t returns the newest revision with `update_time <= t`; a
tombstone (`removed`) hides the item from its time on (DESIGN §4).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId


@dataclass(frozen=True, slots=True)
class Revision:
    """One version of one item (DESIGN §4).

    `data` is the serialized payload, empty for a tombstone (`removed`).
    Every revision written by one commit shares its `update_time` and `commit_id`.
    """

    item_id: ItemId
    table: str
    chunk_id: ChunkId
    data: bytes
    insert_time: int
    update_time: int
    removed: bool
    author: PeerId
    commit_id: CommitId

    @property
    def kind(self) -> str:
        """What this revision did to its item: 'inserted' (it is the item's first
        revision), 'updated' or 'removed'."""
        if self.removed:
            return "removed"
        return "inserted" if self.insert_time == self.update_time else "updated"


# The view a commit comes from unless one is named (`mapctl --view`); a label
# leaves it out, as git leaves out the default branch.
DEFAULT_VIEW = "main"


@dataclass(frozen=True, slots=True)
class CommitRecord:
    """What one commit did: id, logical time, author, message, chunks touched.

    `author_name` is the writer's name (`init --name`) and `view` the view it
    committed from, both as the writer stamped them; empty in records written
    before they were kept, and for library transactions outside any view.
    """

    id: CommitId
    time: int
    author: PeerId
    message: str
    chunks: tuple[ChunkId, ...]
    author_name: str = ""
    view: str = ""


def author_label(record: CommitRecord, known: str = "") -> str:
    """Who committed, for people: "robot1/bob" (name / view), "robot1" from the
    main view, or the short id when no name is known.

    Args:
        known: the author's name as known otherwise (config, member list), for
            records that carry none.
    """
    name = record.author_name or known or record.author.short
    return f"{name}/{record.view}" if record.view not in ("", DEFAULT_VIEW) else name


def number_commits(records: Iterable[CommitRecord]) -> dict[CommitId, int]:
    """Sequence numbers 1..n in commit order (Lamport time, then id, as `log`
    sorts): the times themselves jump, since every message ticks the clock."""
    ordered = sorted(records, key=lambda r: (r.time, r.id))
    return {r.id: n for n, r in enumerate(ordered, start=1)}


def revision_at(revisions: Sequence[Revision], time: int) -> Revision | None:
    """The newest revision written at or before `time`, tombstones included.

    `revisions` must be sorted by `update_time`, oldest first.
    """
    found = None
    for revision in revisions:
        if revision.update_time > time:
            break
        found = revision
    return found


def visible_at(revisions: Sequence[Revision], time: int) -> Revision | None:
    """The item as seen at `time`: `revision_at`, or None if absent or removed."""
    revision = revision_at(revisions, time)
    if revision is None or revision.removed:
        return None
    return revision


def changed_between(revisions: Iterable[Revision], after: int, until: int) -> list[Revision]:
    """The revisions written in the time interval (after, until]."""
    return [r for r in revisions if after < r.update_time <= until]


def change_kind(revision: Revision, previous: Revision | None) -> str:
    """How `revision` changed the item: 'inserted', 'updated' or 'removed'."""
    if revision.removed:
        return "removed"
    if previous is None or previous.removed:
        return "inserted"
    return "updated"


class ItemHistory:
    """All revisions of one item, oldest first; appends keep the order."""

    __slots__ = ("_revisions",)

    def __init__(self, revisions: Iterable[Revision] = ()) -> None:
        self._revisions: list[Revision] = sorted(revisions, key=lambda r: r.update_time)

    def add(self, revision: Revision) -> None:
        """Record a revision; a revision at an existing time replaces nothing.

        Raises:
            ValueError: a revision with the same update time is already recorded
                (one commit writes an item once).
        """
        if any(r.update_time == revision.update_time for r in self._revisions):
            raise ValueError(
                f"item {revision.item_id} already has a revision at time {revision.update_time}"
            )
        self._revisions.append(revision)
        self._revisions.sort(key=lambda r: r.update_time)

    @property
    def revisions(self) -> Sequence[Revision]:
        """Every revision, oldest first."""
        return tuple(self._revisions)

    def latest(self) -> Revision | None:
        """The newest revision, tombstone or not."""
        return self._revisions[-1] if self._revisions else None

    def at(self, time: int) -> Revision | None:
        """See `visible_at`."""
        return visible_at(self._revisions, time)
