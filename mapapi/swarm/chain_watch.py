"""Holders compare their histories (issue 18 §3): now and then each chunk's
leader sends its members the hash-chain link of its latest commit
(`core/chain.py`); a member whose own link at that position differs holds
another history, and says so loudly (an error in peer.log, `diverged`).
"""

from __future__ import annotations

import asyncio
import logging

from mapapi.core.errors import MapError
from mapapi.core.ids import ChunkId
from mapapi.net.messages import ChainHead
from mapapi.net.rpc import Request, Rpc
from mapapi.swarm.group_state import AddressFn
from mapapi.swarm.groups import RaftGroups

log = logging.getLogger(__name__)

COMPARE_EVERY = 5.0
"""Seconds between two rounds of heads sent by each chunk's leader."""


class ChainWatch:
    """Compares this peer's chains with its chunks' leaders' (see the module docstring).

    Args:
        groups: this peer's Raft groups (which chunks it leads, and their members).
        rpc: sends and serves `ChainHead` notifications.
        address: where a peer is reached now.
    """

    def __init__(self, groups: RaftGroups, rpc: Rpc, address: AddressFn) -> None:
        self.groups = groups
        self.rpc = rpc
        self._address = address
        self.diverged: dict[ChunkId, str] = {}  # chunk -> what differs, for peer status and fsck
        self._task: asyncio.Task[None] | None = None
        rpc.register(ChainHead, self.rpc_chain_head)

    def start(self, every: float = COMPARE_EVERY) -> None:
        """Send heads every `every` seconds from the chunks this peer leads."""
        self._task = asyncio.get_running_loop().create_task(self._rounds(every))

    async def close(self) -> None:
        """Stop sending heads."""
        if self._task is not None:
            self._task.cancel()
            await asyncio.gather(self._task, return_exceptions=True)
            self._task = None

    async def _rounds(self, every: float) -> None:
        while True:
            await asyncio.sleep(every)
            self.announce()

    def announce(self) -> None:
        """Send each member of every chunk this peer leads the chunk's head."""
        store = self.groups.store
        for chunk in self.groups.led():
            count = store.chain_length(chunk)
            head = store.chain_at(chunk, count) if count else None
            if head is None:
                continue
            for member in self.groups.members(chunk):
                try:
                    self.rpc.notify(self._address(member), ChainHead(chunk, count, head))
                except MapError as exc:  # the next round tries again
                    log.debug("chain head of %s not sent to %s: %s", chunk.short, member, exc)

    def rpc_chain_head(self, req: Request) -> None:
        """Compare a leader's head with this replica's link at the same position."""
        head: ChainHead = req.body
        mine = self.groups.store.chain_at(head.chunk, head.count)
        if mine is None or mine == head.link:
            return  # not there yet (catching up), or the same history
        what = (
            f"chunk {head.chunk.short}: commit {head.count} differs from the leader's "
            f"({req.sender.short}); this replica holds another history: run `mapctl fsck`"
        )
        if self.diverged.get(head.chunk) != what:
            log.error("%s", what)
        self.diverged[head.chunk] = what
