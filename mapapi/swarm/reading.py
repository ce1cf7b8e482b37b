"""Reading a peer's map in a swarm: a chunk not held here is fetched first (its
holders found by asking the members), and a read of a chunk waits while a
writer holds its lock, so no commit at or before the read time can still
arrive (DESIGN §5). Alone (no swarm), reads go straight to the store.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from mapapi.core.errors import ChunkNotFound

if TYPE_CHECKING:
    from mapapi.core.history import Revision
    from mapapi.core.ids import ChunkId, ItemId
    from mapapi.store.base import ReplicaStore
    from mapapi.swarm.node import Swarm


async def read(
    store: ReplicaStore, swarm: Swarm | None, item_id: ItemId, time: int
) -> Revision | None:
    """The item at `time`; in a swarm, an item of a chunk not held here is
    fetched first (its chunk is found by asking the members)."""
    revision = store.read(item_id, time)
    if swarm is None:
        return revision
    if revision is None and store.item_chunk(item_id) is None:
        try:
            found = await swarm.replicator.find_holders(item=item_id)
        except ChunkNotFound:
            return None
        if found.chunk is not None:
            await swarm.replicator.participate(found.chunk)
    chunk = store.item_chunk(item_id)
    if chunk is not None:
        await swarm.locks.wait_readable(chunk)
    return store.read(item_id, time)


async def scan(
    store: ReplicaStore, swarm: Swarm | None, time: int, table: str, chunk: ChunkId | None
) -> list[Revision]:
    """Items visible at `time` in a table or chunk; a chunk not held here is
    fetched first."""
    if swarm is not None:
        if chunk is not None and chunk not in {c.id for c in store.chunks()}:
            await swarm.replicator.participate(chunk)
        chunks = [chunk] if chunk is not None else [c.id for c in store.chunks(table)]
        for each in chunks:
            await swarm.locks.wait_readable(each)
    return store.scan(time, table=table, chunk=chunk)
