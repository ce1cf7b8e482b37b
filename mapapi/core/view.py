"""`View`: a transaction persisted between commands (pure data, no I/O).

Plus the pure rules of `resolve`: which change settles a conflict, and whether
that would discard an edit the view staged after the conflict (DESIGN §9).
"""

from __future__ import annotations

import shlex
from dataclasses import dataclass, field
from typing import Literal

from mapapi.core.change import Change, Conflict, Op
from mapapi.core.ids import ChunkId, ItemId
from mapapi.core.transaction import Isolation

Scope = tuple[str, ChunkId | None]
Side = Literal["ours", "theirs"]

DEFAULT_VIEW = "main"


def mapctl_in(view: str) -> str:
    """The `mapctl` command line that works in `view`, for hints: a hint that
    left out `--view` would send the user to fix the default view instead."""
    return "mapctl" if view == DEFAULT_VIEW else f"mapctl --view {shlex.quote(view)}"


@dataclass
class View:
    """A named view: begin time, staged changes, open conflicts and, for
    serializable views, what its reads covered (validated at commit).

    A failed commit stages only the changes that did not conflict, so a change
    staged for a conflicting item was staged after the conflict: the user's own
    merge, which `resolve` must not drop silently.
    """

    name: str
    begin_time: int
    isolation: Isolation = "snapshot"
    changes: list[Change] = field(default_factory=list)
    conflicts: list[Conflict] = field(default_factory=list)
    read_set: set[ItemId] = field(default_factory=set)
    scopes: set[Scope] = field(default_factory=set)
    stale: bool = False  # reads this peer's replicas as they are (`Peer.begin(stale=True)`)

    def staged_since_conflict(self) -> dict[ItemId, Change]:
        """Per conflicting item, the change staged after the conflict, if any."""
        conflicting = {c.item_id for c in self.conflicts}
        return {c.item_id: c for c in self.changes if c.item_id in conflicting}


def settle(
    conflict: Conflict, staged: Change | None, side: Side, edited: bytes | None = None
) -> Change | None:
    """The change that settles one conflict (None: keep theirs, stage nothing).

    Args:
        conflict: base, ours (as committed) and theirs.
        staged: what the view staged for the item after the conflict, if anything;
            "ours" means what the view has staged now, so this wins over `conflict.ours`.
        side: the side to keep.
        edited: a payload that replaces both sides (an update).
    """
    if edited is not None:
        return Change(Op.UPDATE, conflict.table, conflict.item_id, conflict.chunk_id, edited)
    if side == "theirs":
        return None
    if staged is not None:
        return staged
    ours = conflict.ours
    if ours is None:
        return None
    if ours.op is Op.REMOVE:
        return None if conflict.theirs.removed else ours
    # The item exists now (theirs), so our insert or update becomes an update.
    return Change(Op.UPDATE, ours.table, ours.item_id, ours.chunk_id, ours.data)


def discards(staged: Change | None, settled: Change | None) -> bool:
    """Whether settling a conflict with `settled` drops the edit `staged` after it."""
    return staged is not None and settled != staged
