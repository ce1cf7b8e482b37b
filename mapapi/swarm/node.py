"""`Swarm`: the networked side of a peer: transport, membership, the Raft group of
each chunk it holds (DESIGN §13), replication and its node on the Chord ring (the
lookup index).

It owns the RPC endpoint and every task behind it; `Peer.start()` creates it and `Peer.close()`
closes it. Membership is simple: a joiner says Hello to any member, learns every member from
the Welcome, and says Hello to each of them; a graceful leave says Bye to all (DESIGN §6).
Every peer is also a node of the Chord ring over the same endpoint (DESIGN §7): it joins the
ring with the swarm and hands its keys over when it leaves. It compares the hash chains of the
chunks it shares with their other holders (`ChainWatch`, issue 18 §3) now and then, and at
once after a rejoin.
"""

from __future__ import annotations

import asyncio
import logging
import random
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from mapapi.core import limits
from mapapi.core.clock import LamportClock
from mapapi.core.errors import JoinRefused, MapError, UsageError
from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, PeerId
from mapapi.lookup.chunk_places import ChunkPlaces
from mapapi.lookup.dht.chord import ChordNode
from mapapi.lookup.spatial import SpatialGrid
from mapapi.lookup.spatial_index import SpatialIndex
from mapapi.net.asking import ask_all
from mapapi.net.codec import Ping, Pong
from mapapi.net.messages import Ack, Bye, Hello, Member, Welcome
from mapapi.net.rpc import Request, Rpc
from mapapi.net.security import Security, own_address
from mapapi.net.shaping import Shaper
from mapapi.net.transport import ZmqTransport
from mapapi.store.base import ReplicaStore
from mapapi.swarm.apply import Outcome
from mapapi.swarm.apply_tx import applier, weight
from mapapi.swarm.chain_watch import ChainWatch, shared
from mapapi.swarm.chunk_state import StoreStates
from mapapi.swarm.commit_check import CommitRule
from mapapi.swarm.final_reads import FinalReads
from mapapi.swarm.group_members import GroupMembers
from mapapi.swarm.groups import Applied, RaftGroups
from mapapi.swarm.liveness import Liveness, LivenessOptions
from mapapi.swarm.log_commit import LogCommits
from mapapi.swarm.membership import Members
from mapapi.swarm.replication import HOLDER_TTL, Replicator
from mapapi.swarm.subscriptions import Subscriptions
from mapapi.swarm.tx_recovery import TxRecovery

AppliedHook = Callable[[CommitRecord, Sequence[Revision]], None]
"""Called with each commit applied here, in each chunk's log order (triggers)."""

log = logging.getLogger(__name__)

MERGE_ROUNDS = 5
"""Stabilize periods between two ring-merge steps through a random member."""


@dataclass(frozen=True, slots=True)
class ChordOptions:
    """Timing of the peer's Chord node and of its holder registrations (seconds).

    Attributes:
        stabilize, fix_fingers, check_predecessor: periods of the ring's repair tasks.
        timeout: deadline of each request to another node.
        holder_ttl: life of a holder registration and a chunk's box (refreshed at 1/3).
        successors: successor list length (also the number of copies of a key).
    """

    stabilize: float = 1.0
    fix_fingers: float = 5.0
    check_predecessor: float = 2.0
    timeout: float = 2.0
    holder_ttl: float = HOLDER_TTL
    successors: int = 4


class Swarm:
    """Networking for one peer (see the module docstring)."""

    def __init__(
        self,
        peer_id: PeerId,
        name: str,
        store: ReplicaStore,
        clock: LamportClock,
        *,
        shaper: Shaper | None = None,
        chord: ChordOptions | None = None,
        places: ChunkPlaces | None = None,
        grid: SpatialGrid | None = None,
        liveness: LivenessOptions | None = None,
        security: Security | None = None,
        on_applied: AppliedHook | None = None,
        rules: Sequence[CommitRule] = (),
    ) -> None:
        self.security = security
        transport = ZmqTransport(peer_id, clock, shaper=shaper, security=security)
        self.rpc = Rpc(transport, on_seen=self._seen)
        self.grid = grid or SpatialGrid()
        self.places = places or ChunkPlaces(store)
        self.index: SpatialIndex | None = None  # made by `start()`, over the ring
        self._name, self._peer_id = name, peer_id
        self.members = Members(Member(peer_id, "", name))
        self.chord_options = chord or ChordOptions()
        self._on_applied = on_applied
        self._rules = tuple(rules)
        # One Raft group per chunk held (DESIGN §13): its members hold it, its log commits.
        self.groups = RaftGroups(
            peer_id,
            store,
            self.rpc,
            address=self.members.address,
            apply=applier(store),  # from any thread: big entries apply in a worker
            on_applied=self._applied,
            peers=lambda: [m.id for m in (*self.members.all(), *self.members.departed())],
            states=StoreStates(store),
            on_members=lambda chunk, peers: self.groups.disk.holders(chunk, peers),
            # idle groups go quiet while the failure detector hears their leaders
            alive=lambda peer: self.liveness.answers(peer),
        )
        self.members.on_added = self.groups.member_back  # (re)started: groups catch it up
        self.groups.applier.weigh = weight(store)  # a decision writes what it prepared
        self.liveness = Liveness(self.rpc, self.members, store, liveness)
        self.log = LogCommits(
            self.groups,
            self.rpc,
            self.members.address,
            clock,
            self._rules,
            answers=self.liveness.answers,
            label=self.members.label,
        )
        self.tx_recovery = TxRecovery(self.log)
        self.group_members = GroupMembers(
            self.groups,
            self.rpc,
            self.members.address,
            remove_after=self.liveness.options.remove_after,
        )
        self.reads = FinalReads(self.log, store)  # what views read is final
        self.replicator = Replicator(
            self.rpc,
            self.members,
            store,
            self.groups,
            self.group_members,
            holder_ttl=self.chord_options.holder_ttl,
            places=self.places,
        )
        self._chord: ChordNode | None = None  # made by `start()`: it needs the address
        self.subscriptions = Subscriptions(
            self.rpc, self.members, store, self.chord_options.holder_ttl
        )
        self._reaper: asyncio.Task[None] | None = None
        self._store = store
        self.chains = ChainWatch(store, self.rpc, self.members.address, *shared(store, peer_id))
        self.rpc.register(Hello, self.rpc_hello)
        self.rpc.register(Bye, self.rpc_bye)
        self.rpc.register(Ping, lambda req: Pong(req.body.payload))
        self._merging: asyncio.Task[None] | None = None

    # -- what the parts report (see `__init__`) ---------------------------------------
    def _seen(self, peer: PeerId) -> None:
        """A message from `peer` arrived: it is alive, and a member is seen now."""
        self.members.touch(peer)
        self.liveness.heard(peer)

    def _applied(self, chunk: ChunkId, applied: Applied) -> None:
        """A committed entry of a chunk's log was applied here (`apply_tx.applier`):
        tell the chunks' boxes and the triggers of a commit it wrote."""
        outcome = applied.result
        if isinstance(outcome, Outcome) and outcome.record is not None:
            self.places.applied(outcome.revisions)
            if self._on_applied is not None:
                self._on_applied(outcome.record, outcome.revisions)

    def ensure_group(self, chunk: ChunkId) -> None:
        """Found a group of one for a chunk this peer holds alone and that has none
        (created here, or held since before it ran on the network)."""
        if self.replicator.holds(chunk):
            return
        holders = self._store.holders(chunk)
        self.groups.found(chunk, holders if self._peer_id in holders else [self._peer_id])

    async def _reap(self, every: float) -> None:
        """Now and then: as a chunk's leader, remove members dead for a while and keep
        the voters odd; as a member long without leader, ask to be one (`GroupMembers`)."""
        while True:
            await asyncio.sleep(every)
            now = asyncio.get_running_loop().time()
            await self.group_members.reap(self.liveness.is_dead, now)
            await self.group_members.rejoin_stuck(self.liveness.answers, now)

    @property
    def address(self) -> str:
        """The endpoint other peers reach this one at."""
        return self.members.me.address or self.rpc.address

    async def start(self, listen: str) -> str:
        """Listen on `listen` (port 0 picks a free port); returns the real address."""
        address = await self.rpc.start(listen)
        options = self.chord_options
        self._chord = ChordNode(
            self.rpc,
            self._peer_id,
            successors=options.successors,
            stabilize_period=options.stabilize,
            fix_fingers_period=options.fix_fingers,
            check_predecessor_period=options.check_predecessor,
            timeout=options.timeout,
        )
        self.advertise(address)
        for chunk in self._store.chunk_ids():  # every group resumes; one held alone gets one
            if not self.groups.resume(chunk):
                self.ensure_group(chunk)
        self.groups.start()
        self.tx_recovery.start()
        every = min(1.0, self.liveness.options.remove_after / 4)
        self._reaper = asyncio.get_running_loop().create_task(self._reap(every), name="reap")
        self._chord.start()
        self.replicator.index_on(self._chord)
        self.index = SpatialIndex(self._chord, self.grid)
        self.places.start(
            self._chord, self.index, options.holder_ttl, lambda: (self._peer_id, self.address)
        )
        self.subscriptions.start(self._chord, self.grid)
        self.liveness.start()
        self.chains.start()
        self._merging = asyncio.get_running_loop().create_task(self._merge_rings(), name="merge")
        return address

    async def _merge_rings(self) -> None:
        """Now and then, merge this node's ring with a random member's: after a
        partition heals, each half has repaired into a ring of its own
        (`ChordNode.merge_through`)."""
        rng = random.Random()
        while True:
            await asyncio.sleep(MERGE_ROUNDS * self.chord_options.stabilize)
            others = [s.member.address for s in self.members.others() if s.member.address]
            if others:
                try:
                    if await self.chord.merge_through(rng.choice(others)):
                        log.info("the lookup ring met another one; merging them")
                except MapError as exc:
                    log.debug("ring merge step failed: %s", exc)

    @property
    def chord(self) -> ChordNode:
        """This peer's node on the Chord ring (after `start()`)."""
        if self._chord is None:
            raise UsageError("the swarm is not started")
        return self._chord

    def advertise(self, address: str) -> None:
        """Tell other peers `address` instead of the bound one (before joining):
        a wildcard host such as tcp://0.0.0.0:7000 is no address they can reach.
        A secure peer's address gets its public key (DESIGN §10)."""
        address = own_address(address, self.security)
        self.members.me = Member(self._peer_id, address, self._name)
        self.members.add(self.members.me)
        if self._chord is not None:
            self._chord.readdress(address)

    # -- membership ------------------------------------------------------------------
    def rpc_hello(self, req: Request) -> Welcome:
        """A peer introduces itself: remember it and tell it every member."""
        member: Member = req.body.member
        if member.id != req.sender or not member.address:
            raise JoinRefused("Hello must carry the sender's own id and address")
        if req.body.index != self.grid.config_fingerprint():
            raise JoinRefused(
                f"the spatial index differs: this swarm uses {self.grid.describe()}; "
                "every peer needs the same [spatial] bounds and cells in .mapapi/config.toml "
                "(set with `mapctl init --bounds ... --cells ...`)"
            )
        if self.members.get(member.id) is None:
            limits.count("members", len(self.members.all()) + 1)  # strangers with new ids
        self.members.add(member)  # and wakes its groups (`RaftGroups.member_back`)
        self.members.touch(member.id)
        return Welcome(tuple(self.members.all()))

    async def call_hello(self, address: str) -> Welcome:
        """Introduce this peer to the member at `address` (its `rpc_hello`); its Welcome.

        Raises:
            JoinRefused, NetworkError: it refused (say another spatial index), or timed out.
        """
        hello = Hello(self.members.me, self.grid.config_fingerprint())
        return await self.rpc.request(address, hello, expect=Welcome)

    def rpc_bye(self, req: Request) -> Ack:
        """A peer stops: unlisted, still in its groups; the ring routes around it."""
        member = self.members.get(req.sender)
        self.members.remove(req.sender)
        if member is not None and member.address and self._chord is not None:
            self._chord.forget(member.address)
        return Ack()

    async def call_bye(self, address: str) -> None:
        """Tell the member at `address` that this peer leaves (its `rpc_bye`)."""
        await self.rpc.request(address, Bye(), timeout=1.0, expect=Ack)

    async def join(self, seed: str) -> list[Member]:
        """Join the swarm through the member at `seed`; returns every member.

        Raises:
            JoinRefused: the seed refused, or answered like no mapapi peer.
            NetworkError: the seed did not answer in time.
        """
        try:
            welcome = await self.call_hello(seed)
        except MapError:
            await self.rpc.forget(seed)  # no reconnecting socket left behind
            raise
        if not any(m.address == seed or m.id != self._peer_id for m in welcome.members):
            raise JoinRefused(f"{seed} answered with no members")
        fresh = [m for m in welcome.members if m.id != self._peer_id and self.members.add(m)]
        answers = await ask_all({m: self.call_hello(m.address) for m in fresh})
        for member, error in answers.failed.items():
            log.warning("member %s at %s did not answer: %s", member.id, member.address, error)
        for answer in answers.ok.values():
            for other in answer.members:
                if other.id != self._peer_id:
                    self.members.add(other)
        await self._join_ring(seed)
        return self.members.all()

    async def _join_ring(self, seed: str) -> None:
        """Join the Chord ring through `seed` (or another member if it fails), then
        announce this peer's chunks again: the keys may have other owners now.
        A peer on the ring already stays where it is."""
        chord = self.chord
        if chord.successors == [chord.me] and chord.predecessor is None:
            others = [s.member.address for s in self.members.others() if s.member.address != seed]
            for address in [seed, *others]:
                try:
                    await chord.join(address)
                    break
                except MapError as exc:
                    log.warning("could not join the lookup ring through %s: %s", address, exc)
            else:
                log.warning("not on the lookup ring: chunks are found by asking the members")
        await self.replicator.refresh()

    async def _back(self, chunk: ChunkId) -> None:
        await self.replicator.register(chunk)
        try:  # compared once caught up: a replica behind is a prefix of any history
            await self.reads.caught_up(chunk)
        except MapError as exc:
            log.warning("chunk %s has not caught up yet: %s", chunk.short, exc)

    async def rejoin(self) -> list[ChunkId]:
        """The chunks this peer shares, their groups resumed at `start`: registered
        again, caught up with their leaders at once, their chains compared."""
        back = await self.replicator.shared()
        await asyncio.gather(*(self._back(chunk) for chunk in back))  # each waits for its leader
        await self.chains.compare(back)
        return back

    async def leave(self) -> None:
        """Withdraw this peer's holder registrations, hand its keys of the ring
        over to its successor, and say Bye to every other member (best effort,
        short deadlines)."""
        try:  # bounded: with its neighbours dead, every step would wait for a timeout
            async with asyncio.timeout(3 * self.chord_options.timeout):
                await self.replicator.withdraw_all()
                await self.subscriptions.withdraw_all()
                if self._chord is not None:
                    await self._chord.leave()
        except (MapError, TimeoutError) as exc:
            log.warning("left the lookup ring uncleanly (entries expire by themselves): %r", exc)
        told = await ask_all(
            {s.member.id: self.call_bye(s.member.address) for s in self.members.others()}
        )
        for peer, error in told.failed.items():  # it sees this peer go silent instead
            log.debug("member %s did not hear Bye: %s", peer.short, error)

    async def close(self) -> None:
        """Stop renewals and the ring's tasks, and close the endpoint (fails
        pending requests)."""
        for task in (self._merging, self._reaper):
            if task is not None:
                task.cancel()
                await asyncio.gather(task, return_exceptions=True)
        await self.chains.close()
        await self.liveness.close()
        await self.tx_recovery.close()
        await self.groups.close()
        await self.replicator.close()
        await self.subscriptions.close()
        if self._chord is not None:
            await self._chord.close()
        await self.rpc.close()
