"""`mapctl fsck`: is the repository's store sound (issue 18 §3)?

Five checks, each reported, none repairing anything:
- the SQLite file itself (`PRAGMA quick_check`: pages, indexes, free lists);
- every stored payload parses as its table's type (a flipped byte usually breaks it);
- every chunk's hash chain (`core/chain.py`) still matches the commits and
  revisions stored now (`swarm/chain_check.py`): a payload changed on disk that
  still parses, a commit gone, a link out of order, a commit with no link;
- the store is not behind its high-water mark (`store/mark.py`): a damaged or
  lost write-ahead log, or older files put back, lose the newest commits
  without any other sign (a rollback);
- no other holder's chain of a chunk was found to differ from this replica's
  (`swarm/chain_watch.py` records it when the peer runs).

It reads the whole store, so it runs in a worker thread, never on the peer's loop.
With `accept`, a rollback is accepted first: forgotten, and the mark set to
the store as it is (the commits are not brought back).
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from mapapi.core.errors import CorruptPayload
from mapapi.swarm.chain_check import check_chain

if TYPE_CHECKING:
    from mapapi.service.ops import Operation
    from mapapi.service.peer import Peer
    from mapapi.store.base import Divergence, Rollback

Json = Any


def rollback_text(found: Rollback) -> str:
    """One line saying how far the store fell behind its high-water mark."""
    when = ""
    if found.noticed:
        when = f", found {time.strftime('%Y-%m-%d %H:%M:%S', time.localtime(found.noticed))}"
    return (
        f"the store is behind what it had recorded: {found.missing} commit(s) missing "
        f"(rolled back: {found.stored} of {found.recorded} commit records left, the newest "
        f"recorded was {found.commit[:8]}{when}); restore a newer copy of .mapapi/store.sqlite* "
        "if there is one (shared chunks are fetched anew from their holders when the peer "
        "rejoins), then `mapctl fsck --accept`"
    )


def divergence_json(found: Divergence) -> Json:
    """A divergence from another holder's chain, as `fsck` and `peer status` show it."""
    return {
        "chunk": found.chunk,
        "peer": found.peer,
        "commit": found.position,
        "noticed": round(found.noticed, 3),
        "detail": found.detail,
    }


def check_repository(peer: Peer, accept: bool = False) -> Json:
    """The report of every check over `peer`'s store (see the module docstring)."""
    store = peer.store
    if accept:
        store.accept_rollback()
    payloads, bad = 0, []
    chains, problems = 0, []
    for chunk in store.chunks():
        table = peer.table(chunk.table)
        for revision in store.chunk_revisions(chunk.id):
            if revision.removed:
                continue
            payloads += 1
            try:
                table.decode(revision.data)
            except CorruptPayload:
                bad.append(
                    f"item {revision.item_id} of table {chunk.table!r} "
                    f"(commit {revision.commit_id.short}) does not parse as {table.type_name}"
                )
        chains += 1
        problems += check_chain(store, chunk.id)
    integrity = store.integrity()
    rollbacks = store.rollbacks()
    diverged = [divergence_json(d) for d in store.divergences()]
    return {
        "store": str(getattr(store, "path", "memory")),
        "ok": not (integrity or bad or problems or rollbacks or diverged),
        "integrity": integrity,
        "payloads": {"checked": payloads, "bad": bad},
        "chains": {"checked": chains, "problems": problems},
        "rollback": {
            "missing": max((r.missing for r in rollbacks), default=0),
            "problems": [rollback_text(r) for r in rollbacks],
        },
        "diverged": diverged,
    }


class FsckOperations:
    """`fsck` over a peer's store."""

    def __init__(self, peer: Peer) -> None:
        self.peer = peer

    def operations(self) -> Mapping[str, Operation]:
        """See `OperationSet`."""
        return {"fsck": self.fsck}

    async def fsck(self, accept: bool = False) -> Json:
        """Check the store, every payload and every chain (in a worker thread); with
        `accept`, accept a rollback first."""
        return await asyncio.to_thread(check_repository, self.peer, accept)
