"""Chunks across peers: commits to every holder, participation, leaving (DESIGN §5-6).

`Replicator` serves the holder's side of the commit protocol (stage a batch
under a current lease, apply it atomically with the unlock), hands a chunk's
full state with history to a newcomer under the chunk's write lock, and tells
the other holders about joins and leaves. It registers this peer as a holder
of each chunk it holds in the Chord index (DESIGN §7, lookup by reference),
refreshing the registrations before their time-to-live runs out, and finds a
chunk's holders there first, falling back to asking every known member. It
also answers `ChunkListQuery` (lookup by peer).
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

from mapapi.core import chain, limits
from mapapi.core.errors import (
    ChunkNotFound,
    CorruptRepoError,
    LockNotHeld,
    MapError,
    NoPeersError,
    NotParticipatingError,
    UsageError,
)
from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId
from mapapi.lookup.dht.announce import Announcements, Entry
from mapapi.lookup.dht.ring import chunk_key
from mapapi.net.codec import Ping, Pong
from mapapi.net.messages import (
    Ack,
    ChunkList,
    ChunkListQuery,
    ChunkPart,
    ChunkSummary,
    CommitAbort,
    CommitApply,
    CommitBatch,
    HolderChange,
    Holders,
    HoldersQuery,
    Member,
    ParticipateRequest,
    TableInfo,
)
from mapapi.net.rpc import Request, Rpc, ask_all, first_answer
from mapapi.store.base import ReplicaStore
from mapapi.store.offload import off_loop
from mapapi.swarm import faults
from mapapi.swarm.commit_check import check_batch
from mapapi.swarm.lock_client import Held, LockService
from mapapi.swarm.membership import Members

if TYPE_CHECKING:
    from mapapi.lookup.chunk_places import ChunkPlaces
    from mapapi.lookup.dht.chord import ChordNode

AppliedHook = Callable[[CommitRecord, Sequence[Revision]], None]
"""Called with each commit another peer applies here, in apply order (triggers)."""

log = logging.getLogger(__name__)

PART_REVISIONS = 1_000
"""Revisions per ChunkPart message: each is decoded on the receiver's event loop
(about 10 ms for 1,000 on the 2-core machine; 5,000 took 40-75 ms, a stall of
the heartbeats each; issue 14 §1)."""
PROBE_TIMEOUT = 2.0  # seconds a holder has to answer a ping before it is asked for a chunk
Progress = Callable[[int, int], None]  # (parts received, parts in all)
HOLDER_TTL = 30.0
"""Seconds a holder registration in the Chord index lives unless its owner refreshes it."""


def _replaced(
    chunk: ChunkId,
    before: list[tuple[CommitId, bytes]],
    after: list[tuple[CommitId, bytes]],
    sender: PeerId,
) -> None:
    """Say so when a fetched replica replaced a history it does not extend: commits
    this replica held alone (never decided by the swarm), or another history."""
    if after[: len(before)] == before:
        return
    gone = {c for c, _ in before} - {c for c, _ in after}
    log.warning(
        "chunk %s: the replica fetched from %s replaced this one's history, which it does "
        "not extend (%d commit(s) held here are not in it)",
        chunk.short,
        sender.short,
        len(gone),
    )


def _state_of(
    store: ReplicaStore, chunk: ChunkId
) -> tuple[list[Revision], dict[CommitId, CommitRecord]]:
    """A chunk's history and its commit records, by id (read in a worker thread)."""
    return store.chunk_revisions(chunk), {c.id: c for c in store.chunk_commits(chunk)}


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


@dataclass
class Staged:
    """A commit batch staged at this holder under `writer`'s lease `token`."""

    writer: PeerId
    token: int
    record: CommitRecord
    revisions: list[Revision]


class Replicator:
    """Replication of the chunks one peer holds."""

    def __init__(
        self,
        rpc: Rpc,
        members: Members,
        locks: LockService,
        store: ReplicaStore,
        *,
        holder_ttl: float = HOLDER_TTL,
        places: ChunkPlaces | None = None,
        on_applied: AppliedHook | None = None,
    ) -> None:
        self.rpc = rpc
        self.members = members
        self.locks = locks
        self.store = store
        self._staged: dict[tuple[ChunkId, CommitId], Staged] = {}
        self.committing: set[CommitId] = set()  # commits this peer writes, until applied here
        self._incoming: dict[ChunkId, list[ChunkPart]] = {}
        self._wanted: dict[ChunkId, int] = {}  # chunks asked for -> participations waiting
        self.progress: dict[ChunkId, Progress] = {}
        self.chord: ChordNode | None = None  # the lookup index, once `index_on` ran
        self.holder_ttl = holder_ttl
        self.announced = Announcements(self._holder_entries, holder_ttl, "holder")
        self.places = places  # the chunks' boxes, kept current if given
        # called with each commit another peer applies here, in apply order
        self._on_applied = on_applied
        for body, handler in (
            (CommitBatch, self.rpc_commit_batch),
            (CommitApply, self.rpc_commit_apply),
            (CommitAbort, self.rpc_commit_abort),
            (ParticipateRequest, self.rpc_participate),
            (ChunkPart, self.rpc_chunk_part),
            (HolderChange, self.rpc_holder_change),
            (HoldersQuery, self.rpc_holders_query),
            (ChunkListQuery, self.rpc_chunk_list_query),
        ):
            rpc.register(body, handler)

    @property
    def me(self) -> PeerId:
        """This peer's id."""
        return self.members.me.id

    def _member(self, peer: PeerId) -> Member:
        return self.members.get(peer) or Member(peer, "")

    def _holders(self, chunk: ChunkId) -> list[PeerId]:
        return self.store.holders(chunk) or [self.me]

    async def lock(
        self, chunk: ChunkId, precheck: Callable[[], Awaitable[None]] | None = None
    ) -> Held:
        """Write-lock `chunk` at all its holders, current when the lock is held
        (a holder that joined or left while we waited is accounted for);
        `precheck` as in `LockService.acquire`."""
        return await self.locks.acquire(
            chunk, self._holders(chunk), current=lambda: self._holders(chunk), precheck=precheck
        )

    # -- the holder's side of a commit ---------------------------------------------
    def rpc_commit_batch(self, req: Request) -> Ack:
        """Stage one chunk's revisions of a commit under a current lease, which
        stays pinned until the commit is applied or dropped (see `mapapi.swarm.lock`)."""
        body: CommitBatch = req.body
        self.locks.check(body.chunk, req.sender, body.token)
        check_batch(self.store, body.chunk, body.record, body.revisions, req.sender)
        self.locks.pin(body.chunk, req.sender, body.token)
        self._staged[(body.chunk, body.record.id)] = Staged(
            req.sender, body.token, body.record, list(body.revisions)
        )
        return Ack()

    async def call_commit_batch(self, address: str, batch: CommitBatch) -> None:
        """Stage `batch` at the holder at `address` (its `rpc_commit_batch`)."""
        await self.rpc.request(address, batch, expect=Ack)

    async def rpc_commit_apply(self, req: Request) -> Ack:
        """Apply a staged batch atomically, then release the writer's lock."""
        body: CommitApply = req.body
        self.locks.check(body.chunk, req.sender, body.token)
        staged = self._staged.pop((body.chunk, body.commit_id), None)
        if staged is None:
            raise LockNotHeld(
                f"no staged batch {body.commit_id.short} for chunk {body.chunk.short}"
            )
        self.apply_batch(staged.record, staged.revisions)
        await self.locks.release_local(body.chunk, req.sender, body.token)
        return Ack()

    async def call_commit_apply(self, address: str, apply: CommitApply) -> None:
        """Have the holder at `address` apply a staged batch (its `rpc_commit_apply`)."""
        await self.rpc.request(address, apply, expect=Ack)

    async def rpc_commit_abort(self, req: Request) -> Ack:
        """Drop a staged batch and release the writer's lock."""
        body: CommitAbort = req.body
        self._staged.pop((body.chunk, body.commit_id), None)
        await self.locks.release_local(body.chunk, req.sender, body.token)
        return Ack()

    async def call_commit_abort(self, address: str, abort: CommitAbort) -> None:
        """Have the holder at `address` drop a staged batch (its `rpc_commit_abort`)."""
        await self.rpc.request(address, abort, expect=Ack)

    def apply_batch(self, record: CommitRecord, revisions: Sequence[Revision]) -> None:
        """Apply another peer's commit to this replica and tell whoever watches."""
        self.store.apply_commit(record, revisions)
        if self.places is not None:
            self.places.applied(revisions)
        if self._on_applied is not None:
            self._on_applied(record, revisions)

    def staged(self, chunk: ChunkId) -> list[Staged]:
        """The batches staged here for `chunk` and not yet applied or dropped."""
        return [b for (c, _), b in sorted(self._staged.items()) if c == chunk]

    def unstage(self, chunk: ChunkId, commit_id: CommitId) -> Staged | None:
        """Take a staged batch out (to apply or drop it); None if there is none."""
        return self._staged.pop((chunk, commit_id), None)

    def applied_here(self, chunk: ChunkId, commit_id: CommitId) -> bool:
        """Whether this replica of `chunk` has the commit's revisions."""
        return any(r.chunk_id == chunk for r in self.store.commit_revisions(commit_id))

    # -- the writer's side ---------------------------------------------------------------
    async def push(
        self,
        held: Sequence[Held],
        record: CommitRecord,
        revisions: Sequence[Revision],
        apply_locally: Callable[[], Awaitable[None]],
    ) -> list[tuple[ChunkId, PeerId]]:
        """Stage the commit at every other holder, apply it here (`apply_locally`,
        in a worker thread: the leases keep being renewed meanwhile), then apply
        it there (which releases their locks). One batch per chunk per holder.

        The local apply decides the commit: until then, a holder that asks how
        it ended hears "pending", and afterwards "applied".

        Returns:
            The (chunk, holder) pairs that did not confirm the apply (they have
            the batch staged, and settle it with this peer or the evictor).

        Raises:
            MapError: a holder refused or did not answer the batch, or our own
                lease ran out (LockNotHeld); nothing was applied anywhere (the
                caller releases the locks).
        """
        by_chunk: dict[ChunkId, list[Revision]] = {h.chunk: [] for h in held}
        for revision in revisions:
            by_chunk[revision.chunk_id].append(revision)
        remote = [
            (h, peer, token) for h in held for peer, token in h.tokens.items() if peer != self.me
        ]
        self.committing.add(record.id)
        try:
            staged = await ask_all(
                {
                    (h.chunk, peer): self.call_commit_batch(
                        self.members.address(peer),
                        CommitBatch(h.chunk, token, record, tuple(by_chunk[h.chunk])),
                    )
                    for h, peer, token in remote
                }
            )
            staged.raise_first()
            await faults.reached("commit.staged")
            for h in held:  # our own replica is fenced too: a lapsed lease here stops us
                if self.me in h.tokens:
                    self.locks.check(h.chunk, self.me, h.tokens[self.me])
            await apply_locally()
        finally:
            self.committing.discard(record.id)
        await faults.reached("commit.applied")
        for h in held:  # the apply ends the remote leases: a renewal now would be refused
            await self.locks.stop_renewing(h)
        applied = await ask_all(
            {
                (h.chunk, peer): self.call_commit_apply(
                    self.members.address(peer), CommitApply(h.chunk, token, record.id)
                )
                for h, peer, token in remote
            }
        )
        for (chunk, peer), error in applied.failed.items():
            log.warning(
                "holder %s did not confirm commit %s on %s: %s",
                peer.short,
                record.id.short,
                chunk.short,
                error,
            )
        return list(applied.failed)

    async def abort(self, held: Sequence[Held], commit_id: CommitId) -> None:
        """Tell every other holder to drop a staged batch (their locks are released
        separately by the caller's `LockService.release`)."""
        dropped = await ask_all(
            {
                (h.chunk, peer): self.call_commit_abort(
                    self.members.address(peer), CommitAbort(h.chunk, 0, commit_id)
                )
                for h in held
                for peer in h.tokens
                if peer != self.me
            }
        )
        for (chunk, peer), error in dropped.failed.items():  # it drops the batch when it settles
            log.debug("holder %s did not drop commit %s on %s: %s", peer, commit_id, chunk, error)

    # -- participation -------------------------------------------------------------------
    async def rpc_participate(self, req: Request) -> Ack:
        """Make the sender a holder: send it the full chunk under the write lock,
        tell the other holders, then release. A sender that is a holder already
        gets the full state again (it may have missed commits), nothing else."""
        chunk: ChunkId = req.body.chunk
        table = self.store.chunk_table(chunk)  # ChunkNotFound if we do not hold it
        newcomer = self._member(req.sender)
        held = await self.lock(chunk)
        try:
            # Read under the lock: another newcomer may have joined meanwhile.
            holders = self._holders(chunk)
            if req.sender in holders:
                await self._send_state(chunk, table, req.sender, holders)
                return Ack()
            await self._send_state(chunk, table, req.sender, [*holders, req.sender])
            others = [p for p in holders if p != self.me]
            await self._tell_holders(others, chunk, held, newcomer, joined=True)
            self.store.set_holders(chunk, [*holders, req.sender])
        finally:
            await self.locks.release(held)
        return Ack()

    async def call_participate(self, address: str, request: ParticipateRequest) -> None:
        """Ask the holder at `address` to make this peer a holder (its
        `rpc_participate`, which sends the chunk before it answers)."""
        await self.rpc.request(address, request, timeout=60.0, expect=Ack)

    async def _send_state(
        self, chunk: ChunkId, table: str, to: PeerId, holders: Sequence[PeerId]
    ) -> None:
        # read in a worker thread (its own connection): a chunk of 100,000 rows would
        # stall this loop, and the newcomer's heartbeats, for seconds (issue 14 §1)
        revisions, commits = await off_loop(self.store, _state_of, self.store, chunk)
        await self._check_history(chunk, commits, revisions)
        info = TableInfo(table, self.store.tables()[table])
        members = tuple(self._member(p) for p in holders)
        pieces = [
            revisions[i : i + PART_REVISIONS] for i in range(0, len(revisions), PART_REVISIONS)
        ]
        pieces = pieces or [[]]
        address = self.members.address(to)
        for index, piece in enumerate(pieces):
            records = tuple(commits[c] for c in sorted({r.commit_id for r in piece}))
            part = ChunkPart(chunk, info, members, tuple(piece), records, index, len(pieces))
            await self.call_chunk_part(address, part)

    async def _check_history(
        self, chunk: ChunkId, commits: dict[CommitId, CommitRecord], revisions: list[Revision]
    ) -> None:
        """Refuse to hand out a replica whose history no longer matches its hash chain:
        the newcomer rebuilds the chain from the history it receives (`install_chunk`),
        so what is sent must be what the chain says (issue 18 §3).

        Raises:
            CorruptRepoError: it does not (logged here; the newcomer asks another holder).
        """
        rebuilt = await asyncio.to_thread(chain.rebuild, chunk, commits, revisions)
        if rebuilt == self.store.chain_links(chunk):
            return
        problem = (
            f"chunk {chunk.short}: the history of this replica no longer matches its hash "
            f"chain, so it is not sent to another peer; run `mapctl fsck` on peer {self.me.short}"
        )
        log.error("%s", problem)
        raise CorruptRepoError(problem)

    async def call_chunk_part(self, address: str, part: ChunkPart) -> None:
        """Send one part of a chunk's state to the newcomer at `address`."""
        await self.rpc.request(address, part, timeout=30.0, expect=Ack)

    async def rpc_chunk_part(self, req: Request) -> Ack:
        """Collect the parts of a chunk; install it atomically with the last one."""
        part: ChunkPart = req.body
        if part.chunk not in self._wanted:
            # Only a holder we asked sends a chunk's state: anything else would
            # overwrite a replica (and its holder set) with what a stranger says.
            raise UsageError(f"chunk {part.chunk.short} was not asked for; part refused")
        limits.parts(part.part, part.parts)
        parts = self._incoming.setdefault(part.chunk, [])
        if parts and part.parts != parts[0].parts:
            self._incoming.pop(part.chunk, None)
            raise UsageError(f"chunk {part.chunk.short}: the parts disagree on their number")
        if part.part != len(parts):
            self._incoming.pop(part.chunk, None)
            raise UsageError(f"chunk {part.chunk.short}: part {part.part} out of order")
        parts.append(part)
        report = self.progress.get(part.chunk)
        if report is not None:
            report(len(parts), part.parts)
        if len(parts) < part.parts:
            return Ack()
        del self._incoming[part.chunk]
        for member in part.holders:
            if member.id != self.me and member.address:
                self.members.add(member)
        before = self.store.chain_links(part.chunk)
        await off_loop(  # one SQL transaction, in a worker thread (issue 14 §1)
            self.store,
            self.store.install_chunk,
            part.chunk,
            part.table.name,
            part.table.type_name,
            [r for p in parts for r in p.revisions],
            list({c.id: c for p in parts for c in p.commits}.values()),
            [m.id for m in part.holders],
        )
        _replaced(part.chunk, before, self.store.chain_links(part.chunk), req.sender)
        if self.places is not None:
            self.places.forget(part.chunk)  # replaced wholesale
        # Batches still in doubt here are settled in the state just installed
        # (taken under the sender's lock, after their writers finished there).
        stale = self.staged(part.chunk)
        for batch in stale:
            self.unstage(part.chunk, batch.record.id)
        if stale:
            await self.locks.preempt(part.chunk, {b.writer for b in stale})
        return Ack()

    def rpc_holder_change(self, req: Request) -> Ack:
        """Another holder joined or left (under the sender's lock)."""
        body: HolderChange = req.body
        self.locks.check(body.chunk, req.sender, body.token)
        holders = set(self.store.holders(body.chunk))
        if body.joined:
            holders.add(body.member.id)
            if body.member.address:
                self.members.add(body.member)
        else:
            holders.discard(body.member.id)
        self.store.set_holders(body.chunk, sorted(holders))
        return Ack()

    async def call_holder_change(self, address: str, change: HolderChange) -> None:
        """Tell the holder at `address` that a holder joined or left (its `rpc_holder_change`)."""
        await self.rpc.request(address, change, expect=Ack)

    async def _tell_holders(
        self, others: Sequence[PeerId], chunk: ChunkId, held: Held, member: Member, *, joined: bool
    ) -> None:
        """Tell `others`, under the lock `held`, that `member` joined or left `chunk`.

        Raises:
            MapError: the first holder that refused or did not answer, once all did.
        """
        told = await ask_all(
            {
                p: self.call_holder_change(
                    self.members.address(p), HolderChange(chunk, held.tokens[p], member, joined)
                )
                for p in others
            }
        )
        told.raise_first()

    async def participate(
        self, chunk: ChunkId, progress: Progress | None = None, *, again: bool = False
    ) -> str:
        """Become a holder of `chunk`, fetching it with its history from a holder.

        Args:
            again: ask even though the local records list this peer as a holder
                (it stopped and the others took it out of their holder sets).

        Returns:
            The chunk's table.

        Raises:
            ChunkNotFound: no known member holds it.
        """
        holders = self.store.holders(chunk)
        if (not again and self.me in holders) or holders == [self.me]:
            return self.store.chunk_table(chunk)
        if progress is not None:
            self.progress[chunk] = progress
        self._wanted[chunk] = self._wanted.get(chunk, 0) + 1
        try:
            last: MapError | None = None
            indexed = await self._find_in_index(chunk)
            tried: set[str] = set()
            for lookup in (indexed, None):  # the index's holders, then the members' answer
                if lookup is None:
                    try:
                        lookup = await self._find_by_asking(HoldersQuery(chunk, None))
                    except MapError:
                        if last is None:
                            raise
                        break
                for member in lookup.holders:
                    if member.id == self.me:
                        continue
                    try:
                        if not await self._ask_to_participate(chunk, member, tried):
                            continue  # asked at these addresses already
                    except MapError as exc:
                        last = exc
                        continue
                    await self.register(chunk)
                    if self.places is not None:
                        await self.places.update([chunk])
                    return self.store.chunk_table(chunk)
            raise last or ChunkNotFound(f"no holder of chunk {chunk} answered")
        finally:
            self.progress.pop(chunk, None)
            self._wanted[chunk] -= 1
            if not self._wanted[chunk]:
                del self._wanted[chunk]
                self._incoming.pop(chunk, None)

    async def _ask_to_participate(self, chunk: ChunkId, holder: Member, tried: set[str]) -> bool:
        """Ask `holder` to make this peer a holder of `chunk` (it sends the chunk),
        at each of its addresses not in `tried` (added to it).

        Returns:
            True once one accepted; False if every address was in `tried`.

        Raises:
            MapError: the last address's error, when none accepted.
        """
        last: MapError | None = None
        for address in self._addresses(holder):
            if address in tried:
                continue
            tried.add(address)
            try:
                # A quick probe first: the index may still list a holder that died
                # (its entry lives 30 s), and the request itself waits a long time.
                await self.rpc.request(address, Ping(), timeout=PROBE_TIMEOUT, expect=Pong)
                await self.call_participate(address, ParticipateRequest(chunk))
                return True
            except MapError as exc:
                last = exc
                log.warning("participating in %s via %s failed: %s", chunk, holder.id, exc)
        if last is not None:
            raise last
        return False

    def _addresses(self, holder: Member) -> list[str]:
        """Where to ask `holder`: first where the member list says it serves, then
        where a lookup said. A holder that restarted serves on another port, and
        the index keeps its old address for as long as the entry lives."""
        known = self.members.get(holder.id)
        return list(dict.fromkeys([*([known.address] if known else []), holder.address]))

    async def leave(self, chunk: ChunkId, force: bool = False, *, keep: bool = False) -> None:
        """Stop holding `chunk`: tell the other holders under the lock, drop it here.

        Args:
            force: leave even as the last holder (its data is lost).
            keep: keep the local replica and its recorded holder set (a peer
                that stops gracefully; `rejoin` makes it a holder again).

        Raises:
            UsageError: this is the last holder and neither `force` nor `keep` is set.
        """
        self.store.chunk_table(chunk)
        if self.store.holders(chunk) in ([], [self.me]):
            if keep:
                return
            if not force:
                raise self._last_holder(chunk)
        held = await self.lock(chunk)
        try:
            others = [p for p in self._holders(chunk) if p != self.me]
            if not others and not (force or keep):  # the others left while we waited
                raise self._last_holder(chunk)
            me = self.members.me
            await self._tell_holders(others, chunk, held, me, joined=False)
            if not keep:
                self.store.drop_chunk(chunk)
        finally:
            await self.locks.release(held)
        await self.unregister(chunk)
        if self.places is not None:
            await self.places.withdraw(chunk)
        # The chunk's lock state stays: writers that still count us as a holder
        # may be queued here, and must get their turn (then see the smaller
        # holder set and lock again without us) rather than wait for a lock
        # that no longer exists; the epoch also keeps growing if we come back.

    async def detach_all(self) -> None:
        """Leave every chunk shared with others but keep the replicas (graceful stop),
        so the others go on committing without this peer."""
        for chunk in self.store.chunk_ids():
            try:
                await self.leave(chunk, keep=True)
            except MapError as exc:
                log.warning("could not leave %s cleanly: %s", chunk.short, exc)

    async def rejoin(self) -> list[ChunkId]:
        """Become a holder again of every chunk this peer shared when it stopped
        (fetching what others committed meanwhile); returns those chunks."""
        back = []
        for chunk in self.store.chunk_ids():
            if [p for p in self.store.holders(chunk) if p != self.me]:
                try:
                    await self.participate(chunk, again=True)
                    back.append(chunk)
                except MapError as exc:
                    log.warning("could not rejoin %s: %s", chunk.short, exc)
        return back

    def admit(self, chunk: ChunkId, writer: PeerId) -> None:
        """Refuse a write lock to a peer this holder does not count as a holder
        (its commits would not reach every replica).

        Raises:
            NotParticipatingError: `writer` is not in this peer's holder set.
        """
        if writer not in self.store.holders(chunk):
            raise NotParticipatingError(
                f"peer {self.me.short} does not count {writer.short} as a holder of chunk "
                f"{chunk.short}; `mapctl chunk participate {chunk}` there to hold it again"
            )

    @staticmethod
    def _last_holder(chunk: ChunkId) -> UsageError:
        return UsageError(
            f"this peer is the last holder of chunk {chunk.short}; leaving would lose "
            "its data: pass --force to drop it anyway"
        )

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
    def rpc_chunk_list_query(self, req: Request) -> ChunkList:
        """The chunks this peer holds (of one table, or of all)."""
        body: ChunkListQuery = req.body
        if body.table and body.table not in self.store.tables():
            raise UsageError(f"no table {body.table!r}")
        chunks = self.store.chunks(body.table or None)
        return ChunkList(tuple(ChunkSummary(c.id, c.table, c.items) for c in chunks))

    # -- the lookup index (DESIGN §7, by reference) --------------------------------------
    def index_on(self, chord: ChordNode) -> None:
        """Use `chord` as the lookup index: announce every chunk only this peer
        holds now (shared ones are announced again as `rejoin` makes this peer
        their holder again) and refresh every announcement in the background."""
        self.chord = chord
        alone = [c for c in self.store.chunk_ids() if self.store.holders(c) in ([], [self.me])]
        self.announced.start(chord, alone)

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
