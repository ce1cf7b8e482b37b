"""`View`: a transaction persisted between commands (pure data, no I/O)."""

from __future__ import annotations

import shlex
from dataclasses import dataclass, field

from mapapi.ids import ChunkId, ItemId
from mapapi.transaction import Change, Conflict, Isolation

Scope = tuple[str, ChunkId | None]

DEFAULT_VIEW = "main"


def mapctl_in(view: str) -> str:
    """The `mapctl` command line that works in `view`, for hints: a hint that
    left out `--view` would send the user to fix the default view instead."""
    return "mapctl" if view == DEFAULT_VIEW else f"mapctl --view {shlex.quote(view)}"


@dataclass
class View:
    """A named view: begin time, staged changes, open conflicts and, for
    serializable views, what its reads covered (validated at commit)."""

    name: str
    begin_time: int
    isolation: Isolation = "snapshot"
    changes: list[Change] = field(default_factory=list)
    conflicts: list[Conflict] = field(default_factory=list)
    read_set: set[ItemId] = field(default_factory=set)
    scopes: set[Scope] = field(default_factory=set)
