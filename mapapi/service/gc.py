"""`mapctl gc`: drop history no one can read any more (issue 14 §4).

A robot that maps for days rewrites its map's items again and again; every
revision stays, so the store grows with time rather than with the map. etcd
compacts its history for the same reason. `gc` drops the revisions no read at
or after a *horizon* sees (`store/compact_sql.py`), and never:

- the newest revision of an item;
- a revision an open view (`mapctl view`, stored) or a transaction begun in this
  process may read: the horizon is at most the oldest begin time among them;
- past the newest commit this peer has heard of (`Peer.now`).

The horizon is `--keep-since TIME` (a logical time, as `--at` takes, or a
commit id: its time) capped as above; `--keep N` keeps each item's N newest
revisions as well (its horizon is the cap alone). With neither, `[history]
retention = N` of `.mapapi/config.toml` gives N. Each holder compacts its own
replicas: chains stay equal (their links never change) and a replica taken from a
compacted holder carries the links its history can no longer rebuild.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mapapi.core.errors import UsageError
from mapapi.core.ids import CommitId
from mapapi.core.transaction import TxState
from mapapi.service.repo import Repository
from mapapi.service.workspace import Workspace
from mapapi.store.file_check import store_bytes

if TYPE_CHECKING:
    from mapapi.service.ops import Operation
    from mapapi.service.peer import Peer

Json = Any


def horizon(peer: Peer, keep_since: int | None) -> tuple[int, str]:
    """The time `gc` may compact up to, and what set it ("asked", "view NAME",
    "a transaction", "now")."""
    bounds = [(peer.now(), "now")]
    if keep_since is not None:
        bounds.append((keep_since, "asked"))
    bounds += [(v.begin_time, f"view {v.name!r}") for v in Workspace(peer).views()]
    bounds += [(t.begin_time, "a transaction") for t in peer.readers if t.state is TxState.OPEN]
    return min(bounds, key=lambda bound: bound[0])


class GcOperations:
    """`gc` over a peer's store."""

    def __init__(self, peer: Peer) -> None:
        self.peer = peer

    def operations(self) -> Mapping[str, Operation]:
        """See `OperationSet`."""
        return {"gc": self.gc}

    async def gc(self, keep_since: int | str | None = None, keep: int | None = None) -> Json:
        """Drop the revisions no reader needs (see the module docstring); what was
        dropped and why the horizon is where it is.

        Raises:
            UsageError: no option and no `[history] retention`, a bad option, a
                commit id that names no commit, or a store `gc` cannot compact.
        """
        store = self.peer.store
        compact = getattr(store, "compact_history", None)
        path = getattr(store, "path", None)
        if compact is None or not isinstance(path, Path):
            raise UsageError("gc compacts a repository's store; this peer's is in memory")
        if keep is not None and keep < 1:
            raise UsageError(
                f"--keep must be 1 or more (the newest revision always stays), not {keep}"
            )
        since = self._time_of(keep_since)
        if since is None and keep is None:
            keep = Repository.find(path.parent.parent).config.retention
            if keep is None:
                raise UsageError(
                    "say what to keep: --keep-since TIME, --keep N, or `retention = N` under "
                    "[history] in .mapapi/config.toml"
                )
        at, reason = horizon(self.peer, since)
        done = await self.peer.off_loop(compact, at, keep)
        return {**asdict(done), "set_by": reason, "store_bytes": store_bytes(path)}

    def _time_of(self, since: int | str | None) -> int | None:
        """A logical time, from a time or a commit id (prefix)."""
        if since is None or isinstance(since, int):
            if since is not None and since < 0:
                raise UsageError(f"--keep-since is a logical time >= 0, not {since}")
            return since
        if since.isdigit():
            return int(since)
        found = self.peer.store.resolve_prefix("commit", since)
        if len(found) != 1:
            raise UsageError(
                f"--keep-since {since!r} is no time and names {len(found) or 'no'} commit(s); "
                "`mapctl log` lists them"
            )
        record = self.peer.store.commit_record(CommitId(found[0]))
        assert record is not None  # resolved from the records
        return record.time
