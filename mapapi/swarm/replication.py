"""Chunks across peers: who holds what, becoming a holder, letting go (DESIGN §6-7, §13).

Holding a chunk is being a member of its Raft group (`swarm/groups.py`): the
group's configuration is the holder set, and the store's follows it. Commits
reach every holder through the group's log (`swarm/log_commit.py`).
`Replicator` makes this peer a holder by joining the group through a holder it
finds (`swarm/group_members.py`: the leader adds it, and its snapshot or log
brings the replica), and lets a chunk go the same way. It registers this peer
as a holder of each chunk it holds in the Chord index (DESIGN §7, lookup by
reference), refreshing the registrations before their time-to-live runs out,
and finds a chunk's holders there first, falling back to asking every known
member. It also answers `ChunkListQuery` (lookup by peer).
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from typing import TYPE_CHECKING

from mapapi.core.errors import ChunkNotFound, MapError, NoPeersError, UsageError
from mapapi.core.ids import ChunkId, ItemId, PeerId
from mapapi.lookup.dht.announce import Announcements, Entry
from mapapi.lookup.dht.ring import chunk_key
from mapapi.net.asking import first_answer
from mapapi.net.codec import Ping, Pong
from mapapi.net.messages import (
    ChunkList,
    ChunkListQuery,
    ChunkSummary,
    Holders,
    HoldersQuery,
    Member,
)
from mapapi.net.rpc import Request, Rpc
from mapapi.store.base import ReplicaStore
from mapapi.store.offload import off_loop
from mapapi.swarm.group_members import GroupMembers
from mapapi.swarm.groups import RaftGroups
from mapapi.swarm.membership import Members

if TYPE_CHECKING:
    from mapapi.lookup.chunk_places import ChunkPlaces
    from mapapi.lookup.dht.chord import ChordNode

log = logging.getLogger(__name__)

PROBE_TIMEOUT = 2.0  # seconds a holder has to answer a ping before it is asked to take us in
Progress = Callable[[int, int], None]  # (parts received, parts in all)
HOLDER_TTL = 90.0
"""Seconds a holder registration (and a chunk's box) in the Chord index lives unless its
owner refreshes it, every third of it. Each refresh costs a lookup and an add per entry: at
30 s, three peers holding 385 chunks (seven 13.6k-pose missions in tiles) sent 420 messages a
second each while idle."""


def encode_holder(member: Member) -> bytes:
    """A holder as the Chord index stores it: 16 id bytes, then the UTF-8 address."""
    return member.id.to_bytes() + member.address.encode()


def decode_holder(raw: bytes) -> Member:
    """The holder `encode_holder` wrote.

    Raises:
        ValueError: too short for an id, or an address that is not UTF-8.
    """
    if len(raw) <= 16:
        raise ValueError(f"a holder entry is an id and an address, got {len(raw)} bytes")
    return Member(PeerId.from_bytes(raw[:16]), raw[16:].decode())


class Replicator:
    """The chunks one peer holds, and how it comes to hold them."""

    def __init__(
        self,
        rpc: Rpc,
        members: Members,
        store: ReplicaStore,
        groups: RaftGroups,
        group_members: GroupMembers,
        *,
        holder_ttl: float = HOLDER_TTL,
        places: ChunkPlaces | None = None,
    ) -> None:
        self.rpc = rpc
        self.members = members
        self.store = store
        self.groups = groups
        self.group_members = group_members
        self.chord: ChordNode | None = None  # the lookup index, once `index_on` ran
        self.holder_ttl = holder_ttl
        self.announced = Announcements(self._holder_entries, holder_ttl, "holder")
        self.places = places  # the chunks' boxes, kept current if given
        self._joining: dict[ChunkId, asyncio.Future[None]] = {}  # joins under way
        rpc.register(HoldersQuery, self.rpc_holders_query)
        rpc.register(ChunkListQuery, self.rpc_chunk_list_query)

    @property
    def me(self) -> PeerId:
        """This peer's id."""
        return self.members.me.id

    def _member(self, peer: PeerId) -> Member:
        return self.members.get(peer) or Member(peer, "")

    def holds(self, chunk: ChunkId) -> bool:
        """Whether this peer is a member of the chunk's group."""
        return self.store.raft_applied_index(chunk) is not None

    # -- participation -------------------------------------------------------------------
    async def participate(
        self, chunk: ChunkId, progress: Progress | None = None, *, again: bool = False
    ) -> str:
        """Become a holder of `chunk`: join its group through a holder, and return
        once the chunk's state and log arrived here. Returns the chunk's table.

        Args:
            again: a holder already asks again (it does not need to: its group
                catches it up by itself; kept for callers that fetch anew).

        Raises:
            ChunkNotFound: no known member holds it.
            RequestTimeout: its state did not arrive in time (asking again waits
                for it anew: this peer stays a member).
        """
        if self.holds(chunk) and self._arrived(chunk):
            return self.store.chunk_table(chunk)
        joining = self._joining.get(chunk)
        if joining is not None:  # another caller here asked already: one join per chunk
            await asyncio.shield(joining)
            return self.store.chunk_table(chunk)
        done = asyncio.get_running_loop().create_future()
        self._joining[chunk] = done
        try:
            table = await self._participate(chunk, progress)
        except BaseException as exc:
            done.set_exception(exc)
            done.exception()  # retrieved: the waiters raise it themselves
            raise
        finally:
            del self._joining[chunk]
        done.set_result(None)
        return table

    def _arrived(self, chunk: ChunkId) -> bool:
        """Whether the chunk's state is here. A peer whose join timed out waiting for
        it (say while the leader sent several snapshots at once) is a member without
        it: asking again joins again, which waits for the state and the log up to
        the change that took it in."""
        try:
            self.store.chunk_table(chunk)
        except ChunkNotFound:
            return False
        return True

    async def _participate(self, chunk: ChunkId, progress: Progress | None) -> str:
        last: MapError | None = None
        indexed = await self._find_in_index(chunk)
        tried: set[PeerId] = set()
        for lookup in (indexed, None):  # the index's holders, then the members' answer
            if lookup is None:
                try:
                    lookup = await self._find_by_asking(HoldersQuery(chunk, None))
                except MapError:
                    if last is None:
                        raise
                    break
            for member in lookup.holders:
                if member.id == self.me or member.id in tried:
                    continue
                tried.add(member.id)
                try:
                    await self._join_through(chunk, member)
                except MapError as exc:
                    last = exc
                    log.warning("joining %s via %s failed: %s", chunk.short, member.id.short, exc)
                    continue
                if progress is not None:
                    progress(1, 1)
                await self.register(chunk)
                if self.places is not None:
                    self.places.forget(chunk)  # replaced wholesale
                    await self.places.update([chunk])
                return self.store.chunk_table(chunk)
        raise last or ChunkNotFound(f"no holder of chunk {chunk} answered")

    async def _join_through(self, chunk: ChunkId, holder: Member) -> None:
        """Join the chunk's group through `holder` (a quick ping first: the index may
        still list a holder that died, for as long as its entry lives)."""
        known = self.members.get(holder.id)
        if known is None or not known.address:
            self.members.add(holder)
        address = self.members.address(holder.id)
        ping = Ping()  # the holder itself must answer there
        await self.rpc.request(address, ping, timeout=PROBE_TIMEOUT, expect=Pong, sender=holder.id)
        await self.group_members.join(chunk, via=holder.id)

    async def leave(self, chunk: ChunkId, force: bool = False) -> None:
        """Stop holding `chunk`: its group lets this peer go, and the replica goes.

        Args:
            force: leave even as the last holder (its data is lost).

        Raises:
            UsageError: this is the last holder and `force` is not set.
        """
        self.store.chunk_table(chunk)
        others = [p for p in self.store.holders(chunk) if p != self.me]
        if not others and not force:
            raise UsageError(
                f"this peer is the last holder of chunk {chunk.short}; leaving would lose "
                "its data: pass --force to drop it anyway"
            )
        if others and self.holds(chunk):
            await self.group_members.leave(chunk)
        else:
            self.groups.drop(chunk)
        self.store.drop_chunk(chunk)
        await self.unregister(chunk)
        if self.places is not None:
            await self.places.withdraw(chunk)

    async def shared(self) -> list[ChunkId]:
        """The chunks this peer holds with others (a restarted peer's groups resume
        by themselves; their chains are compared at once)."""

        def read() -> list[ChunkId]:
            return [
                c
                for c in self.store.chunk_ids()
                if self.holds(c) and [p for p in self.store.holders(c) if p != self.me]
            ]

        # In one worker: two reads per chunk on the loop would each wait for the
        # interpreter lock behind a busy thread, hundreds of times at start.
        return await off_loop(self.store, read)

    # -- finding holders -------------------------------------------------------------------
    def rpc_holders_query(self, req: Request) -> Holders:
        """Answer who holds a chunk (or an item's chunk), if this peer holds it."""
        body: HoldersQuery = req.body
        chunk = body.chunk
        if chunk is None and body.item is not None:
            chunk = self.store.item_chunk(body.item)
        if chunk is None or self.me not in self.store.holders(chunk):
            return Holders(None, "", ())
        members = tuple(self._member(p) for p in self.store.holders(chunk))
        return Holders(chunk, self.store.chunk_table(chunk), members)

    async def call_holders_query(self, address: str, query: HoldersQuery) -> Holders:
        """Ask the peer at `address` who holds a chunk (its `rpc_holders_query`)."""
        return await self.rpc.request(address, query, expect=Holders)

    async def find_holders(
        self, *, chunk: ChunkId | None = None, item: ItemId | None = None
    ) -> Holders:
        """Who holds `chunk` (or `item`'s chunk): a chunk is looked up in the Chord
        index first; otherwise, or when the index knows no holder, every known
        member is asked and the first answer wins. The index does not know a
        chunk's table: its `Holders.table` is empty.

        Raises:
            NoPeersError: the index knows no holder and this peer no other member.
            ChunkNotFound: nobody answered with a holder.
        """
        if chunk is not None:
            indexed = await self._find_in_index(chunk)
            if indexed is not None:
                return indexed
        return await self._find_by_asking(HoldersQuery(chunk, item))

    async def _find_in_index(self, chunk: ChunkId) -> Holders | None:
        """The holders the Chord index lists for `chunk` (this peer left out), or
        None when it lists none or cannot be reached (logged)."""
        if self.chord is None:
            return None
        try:
            raw = await self.chord.get(chunk_key(chunk))
        except MapError as exc:
            log.warning("the lookup index did not answer for %s: %s", chunk.short, exc)
            return None
        found: dict[PeerId, Member] = {}
        for entry in sorted(raw):
            try:
                member = decode_holder(entry)
            except ValueError as exc:
                log.warning("bad holder entry for %s in the index: %s", chunk.short, exc)
                continue
            if member.id != self.me:
                found[member.id] = member
        return Holders(chunk, "", tuple(found.values())) if found else None

    async def _find_by_asking(self, query: HoldersQuery) -> Holders:
        others = self.members.others()
        if not others:
            raise NoPeersError("this peer knows no other peer; `mapctl join ADDR` first")
        asks = [self.call_holders_query(s.member.address, query) for s in others]
        answer = await first_answer(asks, lambda holders: bool(holders.holders))
        if answer is not None:
            return answer
        what = f"chunk {query.chunk}" if query.chunk else f"item {query.item}"
        raise ChunkNotFound(f"no known peer holds {what}")

    # -- lookup by peer ------------------------------------------------------------------
    async def rpc_chunk_list_query(self, req: Request) -> ChunkList:
        """The chunks this peer holds (of one table, or of all), counted in a worker
        (counting reads every revision)."""
        body: ChunkListQuery = req.body
        if body.table and body.table not in self.store.tables():
            raise UsageError(f"no table {body.table!r}")
        chunks = await off_loop(self.store, self.store.chunks, body.table or None)
        return ChunkList(tuple(ChunkSummary(c.id, c.table, c.items) for c in chunks))

    # -- the lookup index (DESIGN §7, by reference) --------------------------------------
    def index_on(self, chord: ChordNode) -> None:
        """Use `chord` as the lookup index: announce every chunk this peer holds and
        refresh every announcement in the background."""
        self.chord = chord
        self.announced.start(chord, self.store.chunk_ids())

    def _holder_entries(self, chunk: ChunkId) -> list[Entry]:
        return [(chunk_key(chunk), encode_holder(self.members.me))]

    async def register(self, chunk: ChunkId) -> None:
        """Announce this peer as a holder of `chunk` in the index, and keep doing
        so until `unregister` (best effort: the refresh task retries)."""
        await self.announced.add(chunk)

    async def unregister(self, chunk: ChunkId) -> None:
        """Take this peer out of `chunk`'s holders in the index (best effort: an
        entry left behind expires with its time-to-live)."""
        await self.announced.remove(chunk)

    async def refresh(self) -> None:
        """Announce every registered chunk again (their time-to-live restarts)."""
        await self.announced.refresh()

    async def withdraw_all(self) -> None:
        """Stop refreshing and take this peer out of the index for every chunk
        (a graceful stop; `index_on` after the next start announces them again)."""
        await self.announced.withdraw_all()
        if self.places is not None:
            await self.places.withdraw_all()

    async def close(self) -> None:
        """Stop the refresh tasks (idempotent)."""
        await self.announced.close()
        if self.places is not None:
            await self.places.close()
