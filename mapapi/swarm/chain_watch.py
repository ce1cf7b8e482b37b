"""Holders compare their histories (issue 18 §3).

Every commit a replica applies extends its chunk's hash chain (`core/chain.py`),
so two holders of a chunk that applied the same commits hold the same chain.
Now and then (and at once when asked, as after a rejoin) this peer sends each
other holder of each chunk it shares the link of its newest commit, numbered
(`ChainHead`, a request); the holder compares it with its own link at that
number and answers with its own link at the lower of the two numbers, which the
asker compares in turn. So one exchange compares both ways where both have the
commit, and a holder that has fewer commits (one still arriving) is compared at
what it has. A link that differs means the two hold different histories: an
error in peer.log on each side that sees it, recorded in the store
(`Store.diverged`, for `mapctl peer status` and an offline `mapctl fsck`) until
a later comparison with that holder agrees past it or the chunk is fetched anew.

Which chunks to compare, and with whom, is given at construction: the holder
sets the chunks' Raft groups keep in the store (`shared`).
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable, Iterable, Sequence

from mapapi.core.errors import MapError, NotParticipatingError
from mapapi.core.ids import ChunkId, PeerId
from mapapi.net.asking import ask_all
from mapapi.net.messages import ChainHead
from mapapi.net.rpc import Request, Rpc
from mapapi.store.base import Divergence, ReplicaStore

log = logging.getLogger(__name__)

COMPARE_EVERY = 5.0
"""Seconds between two rounds of comparisons (of the chunks whose chain grew here)."""
FULL_ROUND = 12
"""Every this many rounds, every shared chunk is compared, grown or not."""
ASK_TIMEOUT = 2.0
"""Seconds another holder has to answer one comparison."""
AT_ONCE = 32
"""Comparisons in flight at a time."""

Chunks = Callable[[], Iterable[ChunkId]]
"""The chunks this peer compares with other holders."""
Peers = Callable[[ChunkId], Sequence[PeerId]]
"""The other holders of a chunk (empty when this peer does not hold it)."""
Address = Callable[[PeerId], str]
"""Where a peer is reached now (raises a MapError when it is not known)."""


def shared(store: ReplicaStore, me: PeerId) -> tuple[Chunks, Peers]:
    """The chunks `me` holds with others in `store`, and a chunk's other holders
    (none if `me` does not hold it), as a `ChainWatch` of that peer asks for them."""

    def chunks() -> list[ChunkId]:
        return [c for c, hs in store.holdings().items() if me in hs and len(hs) > 1]

    def peers(chunk: ChunkId) -> list[PeerId]:
        holders = store.holders(chunk)
        return [p for p in holders if p != me] if me in holders else []

    return chunks, peers


class ChainWatch:
    """Compares this peer's chains with the other holders' (see the module docstring).

    Args:
        store: this peer's replicas, their chains and the divergences recorded.
        rpc: sends and serves `ChainHead`.
        address: where a peer is reached.
        chunks: which chunks to compare in each round.
        peers: with whom to compare a chunk, and whose heads to accept for it.
    """

    def __init__(
        self, store: ReplicaStore, rpc: Rpc, address: Address, chunks: Chunks, peers: Peers
    ) -> None:
        self.store = store
        self.rpc = rpc
        self._address = address
        self._chunks = chunks
        self._peers = peers
        self._compared: dict[tuple[ChunkId, PeerId], int] = {}  # our length when last compared
        self._task: asyncio.Task[None] | None = None
        rpc.register(ChainHead, self.rpc_chain_head)

    @property
    def diverged(self) -> dict[ChunkId, str]:
        """Each chunk whose chain differs from a holder's: what differs."""
        return {d.chunk: d.detail for d in self.store.divergences()}

    def start(self, every: float = COMPARE_EVERY) -> None:
        """Compare every `every` seconds, in the background, until `close`."""
        self._task = asyncio.get_running_loop().create_task(self._rounds(every), name="chains")

    async def close(self) -> None:
        """Stop comparing."""
        if self._task is not None:
            self._task.cancel()
            await asyncio.gather(self._task, return_exceptions=True)
            self._task = None

    async def _rounds(self, every: float) -> None:
        rounds = 0
        while True:
            await asyncio.sleep(every)
            rounds += 1
            await self.compare(grown_only=rounds % FULL_ROUND != 0)

    async def compare(
        self, chunks: Iterable[ChunkId] | None = None, *, grown_only: bool = False
    ) -> None:
        """Compare `chunks` (default: every chunk given at construction) with their
        other holders now; a holder that does not answer is compared next time.

        Args:
            grown_only: skip a chunk and holder compared since with the chain as long.
        """
        asks = []
        for chunk in self._chunks() if chunks is None else chunks:
            count = self.store.chain_length(chunk)
            for peer in self._peers(chunk):
                if not (grown_only and self._compared.get((chunk, peer)) == count):
                    asks.append((chunk, peer, count))
        for start in range(0, len(asks), AT_ONCE):
            batch = asks[start : start + AT_ONCE]
            done = await ask_all({(c, p): self._exchange(c, p, n) for c, p, n in batch})
            for (chunk, peer), error in done.failed.items():
                log.debug("chain of %s not compared with %s: %s", chunk.short, peer.short, error)

    async def _exchange(self, chunk: ChunkId, peer: PeerId, count: int) -> None:
        link = self.store.chain_at(chunk, count) or b""
        address = self._address(peer)
        theirs = await self.call_chain_head(address, ChainHead(chunk, count, link))
        differs = self._compare(chunk, peer, theirs.count, theirs.link)
        if differs and theirs.count < count:
            # They have fewer commits and could not compare at ours: ask again at theirs,
            # so they see it too.
            mine = self.store.chain_at(chunk, theirs.count) or b""
            await self.call_chain_head(address, ChainHead(chunk, theirs.count, mine))
        self._compared[(chunk, peer)] = count

    async def call_chain_head(self, address: str, head: ChainHead) -> ChainHead:
        """Send our link at `head.count` to the holder at `address`; its link at the
        lower of its count and ours (its `rpc_chain_head`)."""
        return await self.rpc.request(address, head, timeout=ASK_TIMEOUT, expect=ChainHead)

    def rpc_chain_head(self, req: Request) -> ChainHead:
        """Compare another holder's link with ours at its number; answer with ours at
        the lower of its number and our chain's length.

        Raises:
            NotParticipatingError: the sender is no other holder of the chunk here.
        """
        head: ChainHead = req.body
        try:
            holder = req.sender in self._peers(head.chunk)
        except MapError:
            holder = False
        if not holder:
            raise NotParticipatingError(
                f"peer {req.sender.short} holds no chunk {head.chunk.short} with this peer"
            )
        self._compare(head.chunk, req.sender, head.count, head.link)
        at = min(head.count, self.store.chain_length(head.chunk))
        return ChainHead(head.chunk, at, self.store.chain_at(head.chunk, at) or b"")

    def _compare(self, chunk: ChunkId, peer: PeerId, count: int, link: bytes) -> bool:
        """Compare `peer`'s link of the chunk's `count`-th commit with ours; whether
        they differ (False when we cannot tell: we have fewer commits)."""
        # A count past any chain (a hostile peer's, up to 2**64) matches no link here.
        mine = self.store.chain_at(chunk, count) if 0 < count < 1 << 62 else None
        if mine is None:
            return False
        known = next(
            (d.position for d in self.store.divergences() if (d.chunk, d.peer) == (chunk, peer)),
            None,
        )
        if mine == link:
            if known is not None and known <= count:  # the same history up to past it
                self.store.agreed(chunk, peer, count)
                log.info("chunk %s: this replica agrees with %s's again", chunk.short, peer.short)
            return False
        if known is None or count < known:
            detail = (
                f"chunk {chunk.short}: commit {count} of its hash chain differs from peer "
                f"{peer.short}'s: one of the two replicas holds another history; run "
                "`mapctl fsck` on both, and `mapctl chunk participate` on the wrong one "
                "to fetch the chunk anew"
            )
            if known is None:
                log.error("%s", detail)
            self.store.diverged(Divergence(chunk, peer, count, detail, 0.0))
        return True
