"""`mapctl fsck`: is the repository's store sound (issue 18 §3)?

Three checks, each reported, none repairing anything:
- the SQLite file itself (`PRAGMA quick_check`: pages, indexes, free lists);
- every stored payload parses as its table's type (a flipped byte usually breaks it);
- every chunk's hash chain (`core/chain.py`) still matches the commits and
  revisions stored now (`swarm/chain_check.py`): a payload changed on disk that
  still parses, a commit gone, a link out of order.

It reads the whole store, so it runs in a worker thread, never on the peer's loop.
"""

from __future__ import annotations

import asyncio
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from mapapi.core.errors import CorruptPayload
from mapapi.swarm.chain_check import check_chain

if TYPE_CHECKING:
    from mapapi.service.ops import Operation
    from mapapi.service.peer import Peer

Json = Any


def check_repository(peer: Peer) -> Json:
    """The report of every check over `peer`'s store (see the module docstring)."""
    store = peer.store
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
        if store.chain_links(chunk.id):
            chains += 1
            problems += check_chain(store, chunk.id)
    integrity = store.integrity()
    return {
        "store": str(getattr(store, "path", "memory")),
        "ok": not (integrity or bad or problems),
        "integrity": integrity,
        "payloads": {"checked": payloads, "bad": bad},
        "chains": {"checked": chains, "problems": problems},
    }


class FsckOperations:
    """`fsck` over a peer's store."""

    def __init__(self, peer: Peer) -> None:
        self.peer = peer

    def operations(self) -> Mapping[str, Operation]:
        """See `OperationSet`."""
        return {"fsck": self.fsck}

    async def fsck(self) -> Json:
        """Check the store, every payload and every chain (in a worker thread)."""
        return await asyncio.to_thread(check_repository, self.peer)
