"""`Peer`: the async public facade; composes the store, clock, commit path and swarm.

A peer works alone on its repository until `start()` puts it on the network
(`Swarm`); from then on every commit goes through the Raft logs of the
chunks it writes (DESIGN §13). It holds no protocol logic of its own and delegates to
`commit`, `transaction`, `swarm` (reads in `reading`, queries by place in
`placed`) and the store.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import TYPE_CHECKING, ParamSpec, TypeVar
from weakref import WeakSet

from mapapi.core.clock import LamportClock
from mapapi.core.errors import ChunkNotFound, NotParticipatingError, UsageError
from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId
from mapapi.core.table import TableDescriptor
from mapapi.core.transaction import Isolation, Transaction
from mapapi.lookup.chunk_places import ChunkPlaces
from mapapi.lookup.spatial import BBox, SpatialGrid
from mapapi.lookup.spatial_index import QueryStats
from mapapi.service.fsck import rollback_text
from mapapi.service.repo import Repository
from mapapi.service.stale import StaleReads
from mapapi.service.tables import Tables, check_replication
from mapapi.store import ChunkInfo, MemoryStore, offload
from mapapi.store.base import ReplicaStore
from mapapi.swarm import reading
from mapapi.swarm.commit import commit_locally, refuse_shared
from mapapi.swarm.placed import Here, PlacedChunk, query_bbox
from mapapi.swarm.triggers import Callback, Triggers

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    from google.protobuf.message import Message

    from mapapi.core.merge import MergePolicy
    from mapapi.net.messages import ChunkSummary, Member
    from mapapi.net.security import Security
    from mapapi.net.shaping import Shaper
    from mapapi.store.labels import Labels, LabelSummary
    from mapapi.swarm.commit_check import CommitRule
    from mapapi.swarm.liveness import LivenessOptions
    from mapapi.swarm.membership import MemberState
    from mapapi.swarm.node import ChordOptions, Swarm
    from mapapi.swarm.replication import Progress
    from mapapi.swarm.subscriptions import Subscription, SubscriptionSpec

log = logging.getLogger(__name__)

P = ParamSpec("P")
T = TypeVar("T")


class Peer:
    """One peer and its local map repository.

    Args:
        rules: what every commit of this peer must keep (`CommitRule`); none
            by default. The application gives its own: `mapapi.app` builds
            peers with the map tables' rules.
    """

    def __init__(
        self,
        store: ReplicaStore,
        peer_id: PeerId | None = None,
        *,
        name: str = "",
        grid: SpatialGrid | None = None,
        security: Security | None = None,
        rules: Sequence[CommitRule] = (),
    ) -> None:
        self.store = store
        self.rules = tuple(rules)  # checked by every commit this peer writes
        self.security = security
        self.id = peer_id or PeerId.new()
        self.name = name or self.id.short
        self.grid = grid or SpatialGrid()
        self.places = ChunkPlaces(store)
        self.triggers = Triggers()
        self.readers: WeakSet[Transaction] = WeakSet()  # begun here: `gc` keeps what they read
        self.clock = LamportClock(store.clock())
        self.swarm: Swarm | None = None
        self._tables = Tables(store)

    @classmethod
    def open(
        cls,
        path: str | Path = ".",
        *,
        rules: Sequence[CommitRule] = (),
        labels: Labels | None = None,
    ) -> Peer:
        """The peer of the repository at (or above) `path` (`rules`: see `Peer`;
        `labels`: see `of`)."""
        return cls.of(Repository.find(path), rules=rules, labels=labels)

    @classmethod
    def of(
        cls, repo: Repository, *, rules: Sequence[CommitRule] = (), labels: Labels | None = None
    ) -> Peer:
        """The peer of `repo`: its store, identity, spatial index geometry and,
        for a secure repository, its keys and trust list (DESIGN §10); `rules`:
        see `Peer`. With `labels` (`mapapi.store.labels`), the store keeps
        their index, from which `scan_labelled` and `label_summaries` answer;
        `mapapi.app` gives the map tables' (rows by mission)."""
        config = repo.config
        security = repo.security()
        return cls(
            repo.open_store(labels),
            config.peer_id,
            name=config.name,
            grid=config.spatial,
            security=security,
            rules=rules,
        )

    @classmethod
    def in_memory(cls, *, rules: Sequence[CommitRule] = ()) -> Peer:
        """A scratch peer on a `MemoryStore` (`rules`: see `Peer`)."""
        return cls(MemoryStore(), rules=rules)

    async def close(self) -> None:
        """Leave the swarm gracefully (if on one) and release the store.

        The peer stays a member of its chunks' groups: the others go on committing
        while a majority of each group's voters is up, and the groups catch this
        peer up when it starts again (DESIGN §13).
        """
        if self.swarm is not None:
            await self.swarm.leave()
            await self.swarm.close()
            self.swarm = None
        await self.triggers.close()
        self.store.close()

    # -- the swarm -----------------------------------------------------------------
    async def start(
        self,
        listen: str = "tcp://127.0.0.1:0",
        *,
        shaper: Shaper | None = None,
        chord: ChordOptions | None = None,
        liveness: LivenessOptions | None = None,
    ) -> str:
        """Put this peer on the network; returns the address others join through.

        Args:
            listen: a zmq endpoint; port 0 picks a free port.
            shaper: simulated latency and bandwidth per link, for experiments.
            chord: periods and timeouts of the lookup ring and the time-to-live
                of holder registrations (`mapapi.swarm.node.ChordOptions`; the
                defaults suit robots on a wireless network).
            liveness: heartbeat period and the silences after which a peer is
                suspected and declared dead (`mapapi.swarm.liveness.LivenessOptions`).
        """
        from mapapi.swarm.node import Swarm  # the network stack loads only when needed

        if self.swarm is not None:
            raise UsageError(f"peer already listens on {self.swarm.address}")
        swarm = Swarm(
            self.id,
            self.name,
            self.store,
            self.clock,
            shaper=shaper,
            chord=chord,
            places=self.places,
            grid=self.grid,
            liveness=liveness,
            security=self.security,
            on_applied=self.triggers.applied,
            rules=self.rules,
        )
        address = await swarm.start(listen)
        self.swarm = swarm
        for lost in self.store.rollbacks():  # loudly, at every start until accepted
            log.error("%s", rollback_text(lost))
        return address

    def _on_swarm(self) -> Swarm:
        if self.swarm is None:
            raise UsageError("this peer is not on the network; start it first")
        return self.swarm

    @property
    def address(self) -> str:
        """The address other peers join through."""
        return self._on_swarm().address

    async def join(self, seed: str) -> list[Member]:
        """Join the swarm through the member listening at `seed`; returns every member.

        A peer that shared chunks before it stopped holds them again (`rejoin`).
        """
        members = await self._on_swarm().join(seed)
        await self.rejoin()
        return members

    async def rejoin(self) -> list[ChunkId]:
        """Hold again the chunks this peer shared before it stopped, catching up on
        what the others committed meanwhile, and compare their hash chains with the
        other holders' at once; returns those chunks."""
        return await self._on_swarm().rejoin()

    def members(self) -> list[MemberState]:
        """The other members of the swarm, with when each was last heard of."""
        return self._on_swarm().members.others()

    async def participate(
        self, chunk_id: ChunkId, progress: Progress | None = None, *, again: bool = False
    ) -> str:
        """Replicate `chunk_id` here: join its Raft group through a holder, receive
        its history (the log, or a snapshot) and every later commit. Returns the
        chunk's table.

        With `again`, nothing more happens for a chunk held already: its group
        catches it up by itself (the flag stays for callers of the lock path)."""
        return await self._on_swarm().replicator.participate(chunk_id, progress, again=again)

    async def leave_chunk(self, chunk_id: ChunkId, *, force: bool = False) -> None:
        """Stop replicating `chunk_id` (the last holder needs `force`)."""
        if self.swarm is None:
            if not force:
                raise UsageError(f"this peer is the only holder of {chunk_id.short}; pass force")
            self.store.drop_chunk(chunk_id)
            return
        await self.swarm.replicator.leave(chunk_id, force)

    def holders(self, chunk_id: ChunkId) -> list[PeerId]:
        """The peers that hold a chunk held here."""
        self.store.chunk_table(chunk_id)
        return self.store.holders(chunk_id) or [self.id]

    def roles(self, chunk_id: ChunkId) -> dict[PeerId, str]:
        """Each holder's role in the chunk's Raft group ("leader", "voter",
        "learner"), as this peer knows it; empty while it is not on the network."""
        holders = self.holders(chunk_id)
        if self.swarm is None or not self.swarm.replicator.holds(chunk_id):
            return {}
        from mapapi.swarm.group_members import roles  # the network stack: loaded on it only

        return roles(self.swarm.groups, chunk_id, holders)

    async def peer_chunks(self, address: str, table: str | None = None) -> list[ChunkSummary]:
        """The chunks the peer at `address` holds (lookup by peer, DESIGN §7).

        Raises:
            NetworkError: it did not answer in time.
        """
        from mapapi.service.control import ask_chunk_list

        rpc = self.swarm.rpc if self.swarm is not None else None
        return await ask_chunk_list(address, table, rpc=rpc, security=self.security)

    async def query_bbox(
        self, box: BBox, table: str | None = None, stats: QueryStats | None = None
    ) -> list[PlacedChunk]:
        """The chunks whose box overlaps `box` (of `table`, if given), with their
        holders, sorted by chunk id (DESIGN §7). On the network the spatial index
        is asked (chunks held here are added even before their announcement
        lands); alone, only the chunks held here are searched. A box partly
        outside the index's bounds is clamped; one fully outside matches nothing.

        Raises:
            QueryError: no owner of the box's cells answered.
        """
        here = Here(self.id, self.name, self.store, self.places, self.grid, self.swarm)
        return await query_bbox(here, box, table, stats)

    async def __aenter__(self) -> Peer:
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.close()

    # -- tables and chunks --------------------------------------------------
    async def create_table(
        self, name: str, message_type: str | type[Message], replication: int = 0
    ) -> TableDescriptor:
        """Create a table of `message_type` (a class or protobuf name); see `Tables.create`."""
        return self._tables.create(name, message_type, replication)

    def tables(self) -> dict[str, TableDescriptor]:
        """Every table of the repository."""
        return {name: self.table(name) for name in self.store.tables()}

    def table(self, name: str) -> TableDescriptor:
        """One table's descriptor."""
        return self._tables.get(name)

    async def create_chunk(self, table: str, replication: int = 0) -> ChunkId:
        """A new, empty chunk of `table` held here (on the network: its group's one
        member, announced in the lookup index); `replication`, 0: its table's factor."""
        self.table(table)
        check_replication(replication)
        chunk_id = ChunkId.new()
        self.store.add_chunk(chunk_id, table, replication)
        self.store.set_holders(chunk_id, [self.id])
        if self.swarm is not None:
            self.swarm.ensure_group(chunk_id)  # others can join it before its first commit
            await self.swarm.replicator.register(chunk_id)
        return chunk_id

    def chunks(self, table: str | None = None) -> list[ChunkInfo]:
        """The chunks this peer holds."""
        if table is not None:
            self.table(table)
        return self.store.chunks(table)

    def chunk_table(self, chunk_id: ChunkId) -> str:
        """The table of a chunk held here.

        Raises:
            NotParticipatingError: this peer does not hold the chunk.
        """
        try:
            return self.store.chunk_table(chunk_id)
        except ChunkNotFound:
            raise NotParticipatingError(
                f"this peer does not hold chunk {chunk_id}; `mapctl chunk participate` first"
            ) from None

    def set_merge_policy(self, table: str, policy: MergePolicy | None) -> None:
        """Install (or with None, remove) the auto-merge policy of a table."""
        self._tables.set_merge_policy(table, policy)

    # -- transactions ---------------------------------------------------------
    def now(self) -> int:
        """The time a transaction begun now reads at: the newest commit time this
        peer has applied (other processes may commit to its store too), or, in a
        swarm, been acknowledged as a writer or pushed by a trigger, whichever is later.

        A view then includes every commit this peer has heard of. Not the Lamport
        clock, which every message advances: a view at the newest commit needs no
        `TimeFloor` at its first read of a chunk that is up to date, where a view at
        the Lamport clock always did (a round of the log per view). That first read
        still catches the chunk up (`Swarm.read_at`), so the view sees every commit
        acknowledged anywhere before it (DESIGN §13).
        """
        newest = self.store.clock()
        if self.swarm is None:
            return newest
        self.clock.advance_to(newest)
        return max(newest, self.swarm.log.acknowledged, self.swarm.subscriptions.newest)

    def begin(
        self, at: int | None = None, *, isolation: Isolation = "snapshot", stale: bool = False
    ) -> Transaction:
        """A transaction reading the map as of now (or of logical time `at`).

        Begun now in a swarm, its first read catches up the chunks it reads and
        moves its time to their newest commit if that is later (`catch_up`), so it
        sees every commit acknowledged before that read, on any peer. `stale`:
        it reads this peer's replicas as they are, asking no one (`service/stale.py`)."""
        if stale:
            if at is not None:
                raise UsageError("a stale view reads the replicas as they are now: no --at")
            tx = Transaction(StaleReads(self), self.store.clock(), self.id, isolation=isolation)
        else:
            now = self.now()
            if at is not None and not 0 <= at <= now:
                raise UsageError(f"time {at} is outside 0..{now} (the newest commit time)")
            if at is not None and at < (floor := self.store.history_floor()):
                raise UsageError(f"time {at} is before {floor}: `mapctl gc` dropped that history")
            begin = now if at is None else at
            tx = Transaction(self, begin, self.id, isolation=isolation, fresh=at is None)
        self.readers.add(tx)
        return tx

    def read_local(self, item_id: ItemId, time: int) -> Revision | None:
        """The newest local revision of an item at or before `time`."""
        return self.store.read(item_id, time)

    async def read(self, item_id: ItemId, time: int) -> Revision | None:
        """The item at `time`; in a swarm, an item of a chunk not held here is
        fetched first (`mapapi.swarm.reading.read`)."""
        return await reading.read(self.store, self.swarm, item_id, time)

    async def scan(self, time: int, table: str, chunk: ChunkId | None) -> list[Revision]:
        """Items visible at `time` in a table or chunk; a chunk not held here is
        fetched first (`mapapi.swarm.reading.scan`)."""
        return await reading.scan(self.store, self.swarm, time, table, chunk)

    async def pin(self, item_id: ItemId, time: int) -> bool:
        """Make the item's chunk final up to `time` before a blind write, best
        effort (`mapapi.swarm.reading.pin`); whether it was."""
        return await reading.pin(self.store, self.swarm, item_id, time)

    async def scan_newest(self, table: str) -> list[Revision]:
        """Every item of `table`, each chunk read at its own caught-up clock (a
        listing: `mapapi.swarm.reading.scan_newest`)."""
        return await reading.scan_newest(self.store, self.swarm, table)

    async def catch_up(
        self,
        time: int,
        *,
        item: ItemId | None = None,
        table: str = "",
        chunk: ChunkId | None = None,
    ) -> int:
        """The time a view begun now (at `time`) reads at once its first read
        (of `item`, or of `chunk`, or of `table`) caught up the chunks it touches
        (`mapapi.swarm.reading.latest`); alone, `time`."""
        moved = await reading.latest(
            self.store, self.swarm, time, item=item, table=table, chunk=chunk
        )
        self.clock.advance_to(moved)
        return moved

    async def scan_labelled(
        self, time: int, labels: Labels, label: str, table: str
    ) -> list[Revision]:
        """The items of `table` labelled `label` by `labels` visible at `time`, by
        id: from the store's index when it keeps one of `labels` (only those rows
        are read), else filtered from the table's rows (`mapapi.store.labels`);
        read in a worker thread."""
        return await reading.scan_labelled(self.store, self.swarm, labels, time, label, table)

    async def labelled_readable(
        self, labels: Labels, names: Sequence[str], tables: Sequence[str], time: int
    ) -> int:
        """A time at which `scan_labelled_now` reads the rows of `tables` labelled
        with `names` as every replica will from now on, seeing every commit
        acknowledged to them (`mapapi.swarm.reading.labelled_readable`); alone,
        `time`."""
        return await reading.labelled_readable(self.store, self.swarm, labels, names, tables, time)

    def scan_labelled_now(
        self, time: int, labels: Labels, label: str, table: str
    ) -> list[Revision]:
        """`scan_labelled` without making chunks final (after `labelled_readable`),
        from any thread: for functions run with `off_loop`."""
        return reading.scan_labelled_now(self.store, labels, time, label, table)

    async def off_loop(self, fn: Callable[P, T], *args: P.args, **kwargs: P.kwargs) -> T:
        """`fn(*args, **kwargs)` in a worker thread with its own connection to the
        store, so the peer keeps serving while it runs (`mapapi.store.offload`;
        on a memory store it runs here). `fn` may read and write the store but
        must not touch asyncio objects: it returns its result."""
        return await offload.off_loop(self.store, fn, *args, **kwargs)

    def label_summaries(
        self, labels: Labels, only: Sequence[str] | None = None
    ) -> list[LabelSummary]:
        """Per label of `labels` (or of those in `only`) and chunk, the live rows
        held here now: how many, their weight and box. Kept by the store when
        it indexes `labels`, else computed from every labelled row."""
        return reading.label_summaries(self.store, labels, only)

    async def commit_transaction(self, tx: Transaction, message: str) -> CommitRecord | None:
        """Validate and apply a transaction: alone, against the store
        (`mapapi.swarm.commit`); in a swarm, through the logs of the chunks it
        writes (`mapapi.swarm.log_commit`), decided alike by every holder."""
        if self.swarm is not None:
            for chunk in sorted({c.chunk_id for c in tx.changes}):
                self.swarm.ensure_group(chunk)  # a chunk made here has a group of one
            done = await self.swarm.log.commit(tx, message)
            if done.record is not None:
                await self._announce(done.record, list(done.revisions))
            return done.record
        refuse_shared(self.store, self.id, tx)
        local = commit_locally(
            self.store, tx, message, self.clock, self._tables.try_merge, self.rules
        )
        if local.record is not None:
            self.triggers.applied(local.record, local.revisions)
            await self._announce(local.record, local.revisions)
        return local.record

    async def _announce(self, record: CommitRecord, revisions: list[Revision]) -> None:
        """What follows a commit of this peer: the chunks' boxes are announced
        (DESIGN §7: a query right after finds them) and remote subscribers told
        (DESIGN §8). In a swarm, the triggers here heard of it as it applied."""
        if self.places.caches(record.chunks):
            self.places.applied(revisions)
        await self.places.update(record.chunks)
        if self.swarm is not None:
            await self.swarm.subscriptions.notify(record, revisions)

    # -- triggers (DESIGN §8) ------------------------------------------------------
    def on_commit(
        self, callback: Callback, *, chunk: ChunkId | None = None, table: str | None = None
    ) -> int:
        """Call `callback(event)` once for every commit applied here from now on
        (this peer's and others') that touches `chunk`, or `table`, or anything;
        in commit order, off the receive loop (see `mapapi.swarm.triggers`). Returns
        the trigger's id for `remove_trigger`."""
        if table is not None:
            self.table(table)
        if chunk is not None:
            self.chunk_table(chunk)
        return self.triggers.add(callback, chunk=chunk, table=table)

    def remove_trigger(self, trigger_id: int) -> bool:
        """Stop a trigger; returns whether it existed."""
        return self.triggers.remove(trigger_id)

    async def subscribe(self, spec: SubscriptionSpec) -> Subscription:
        """Hear about every commit, by any peer, that changes an item inside
        `spec`'s region (of its table, matching its filters): the matching
        revisions arrive in the subscription's `events` (DESIGN §8).

        Raises:
            UsageError: not on the network, or a region outside the index.
        """
        return await self._on_swarm().subscriptions.subscribe(spec)

    async def unsubscribe(self, subscription: Subscription) -> bool:
        """Cancel a subscription; returns whether it was active."""
        return await self._on_swarm().subscriptions.cancel(subscription.id)

    # -- history -------------------------------------------------------------
    def log(self, limit: int | None = None) -> list[CommitRecord]:
        """Commit records, newest first."""
        return self.store.commits(limit)

    def history(self, item_id: ItemId) -> list[Revision]:
        """Every revision of an item, oldest first."""
        return self.store.history(item_id)

    def commit_record(self, commit_id: CommitId) -> CommitRecord | None:
        """One commit record."""
        return self.store.commit_record(commit_id)

    def commit_revisions(self, commit_id: CommitId) -> list[Revision]:
        """The revisions one commit wrote."""
        return self.store.commit_revisions(commit_id)
