"""Reads that never change (DESIGN §13): a view reads a chunk's replica only once
it is final up to the view's time, caught up with the chunk's leader and closed
against later commits stamped at or before that time (`LogCommits.read_at`).

`FinalReads` remembers, per chunk, the time up to which this replica is known to
be final, so a view's later reads of the chunk, and other views at or before that
time, cost nothing more; a view begun now catches the replica up at its first
read (`caught_up`), which also tells it the chunk's clock (`reading.latest`).
"""

from __future__ import annotations

from mapapi.core.ids import ChunkId
from mapapi.store.base import ReplicaStore
from mapapi.swarm.groups import PROPOSE_TIMEOUT
from mapapi.swarm.log_commit import LogCommits


class FinalReads:
    """Makes this peer's replicas final for the views that read them.

    Args:
        log: proposes floors and catches replicas up through the chunks' logs.
        store: the replicas (a chunk with no group here is read as it is).
    """

    def __init__(self, log: LogCommits, store: ReplicaStore) -> None:
        self.log = log
        self.store = store
        self._final: dict[ChunkId, int] = {}  # chunk -> the time up to which reads are final

    def _holds(self, chunk: ChunkId) -> bool:
        return self.store.raft_applied_index(chunk) is not None

    async def read_at(self, chunk: ChunkId, time: int, timeout: float = PROPOSE_TIMEOUT) -> None:  # noqa: ASYNC109
        """Make this replica of `chunk` final up to `time` before a view reads it
        there (`LogCommits.read_at`: caught up with the leader, and no later commit
        stamped at or before `time`); once done for a time, later reads at or
        before it need nothing more.

        Raises:
            NoQuorum, NotChunkLeader, RequestTimeout: the chunk's group could not
                confirm in time.
        """
        if self._final.get(chunk, -1) >= time or not self._holds(chunk):
            return
        await self.log.read_at(chunk, time, timeout)
        self._final[chunk] = max(self._final.get(chunk, -1), time)

    async def caught_up(self, chunk: ChunkId) -> int:
        """Catch this replica of `chunk` up with its leader, as a view begun now
        needs to see every commit acknowledged before (ReadIndex); returns the
        chunk's clock then, up to which its reads are final.

        Raises:
            NoQuorum, NotChunkLeader, RequestTimeout: the chunk's group could not
                confirm in time.
        """
        if not self._holds(chunk):
            return self.store.raft_time(chunk)
        time = await self.log.caught_up(chunk)
        self._final[chunk] = max(self._final.get(chunk, -1), time)
        return time
