"""The multi-Raft shell: one Raft group per chunk this peer holds (DESIGN §13).

`RaftGroups` drives a pure `RaftNode` (`swarm/raft.py`) per chunk through the Ready loop: it
persists each `Ready` before sending its messages (`ready_disk.py`), and hands committed entries to
`GroupApplier` (`group_apply.py`), which applies them with the applied index in one store
transaction (an entry lands once, even across a crash), and answers their proposers. One ticker
drives every group; all messages for one peer leave in one `RaftBatch` per round
(`swarm/raft_mail.py`): many groups' heartbeats cost one frame per pair of peers. With a
`StoreStates`, logs are compacted into snapshots of the chunk's state, which a member that joins or
lags far behind installs (`swarm/chunk_state.py`). A peer's node id is the top 63 bits of its
`PeerId` (`node_id`), the same in every group: configurations name peers.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import random
import time
from collections.abc import Callable, Iterable
from dataclasses import replace
from functools import partial

from mapapi.core.errors import CorruptRepoError, NotChunkLeader, PeerUnavailable
from mapapi.core.ids import ChunkId, PeerId
from mapapi.net.messages import Ack, RaftBatch
from mapapi.net.rpc import Request, Rpc
from mapapi.store.base import ReplicaStore
from mapapi.store.offload import off_loop
from mapapi.swarm.chunk_state import StoreStates
from mapapi.swarm.group_apply import AppliedHook, GroupApplier
from mapapi.swarm.group_state import (
    AddressFn,
    Applied,
    ApplyFn,
    GroupState,
    halted,
    persist_founding,
    step_batch,
)
from mapapi.swarm.raft import RaftNode
from mapapi.swarm.raft_mail import RaftMail
from mapapi.swarm.raft_types import (
    ConfChange,
    Config,
    NotLeader,
    PersistentState,
    RaftOptions,
    Ready,
    Role,
)
from mapapi.swarm.raft_wire import node_id, state_of
from mapapi.swarm.ready_disk import ReadyDisk

log = logging.getLogger(__name__)

TICK_SECONDS = 0.05
"""Seconds per Raft tick: a dead leader is replaced in 0.5-1 s (10-20 ticks)."""
PROPOSE_TIMEOUT = 5.0
"""Seconds a proposal waits to be committed and applied."""
COMPACT_AFTER = 1000
"""Entries a group applies past its last snapshot before its log is compacted."""


class RaftGroups:
    """Every Raft group of this peer (see the module docstring).

    Args:
        me, store, rpc, address: this peer; where each group's state and log persist;
            sends and receives `RaftBatch`es; where a peer is reached now.
        apply: applies a committed entry's effect to the store (any thread);
            `on_applied` is told on the loop what it did.
        peers: every peer a node id may stand for (the member list), to map ids back.
        options: the core's tunables; `seed` makes election timeouts reproducible.
        on_change: called after each Ready round that changed a role, a leader or sent.
        states: takes and installs chunks' states as snapshots (without it, logs
            are never compacted); `compact_after` entries past the last one.
        on_members: told a group's members (those it can name) at each change here.
        alive: the peer-level failure detector; with it idle groups go quiet.
    """

    def __init__(
        self,
        me: PeerId,
        store: ReplicaStore,
        rpc: Rpc,
        address: AddressFn,
        apply: ApplyFn,
        peers: Callable[[], Iterable[PeerId]],
        options: RaftOptions | None = None,
        seed: int | None = None,
        on_change: Callable[[], None] | None = None,
        states: StoreStates | None = None,
        compact_after: int = COMPACT_AFTER,
        on_members: Callable[[ChunkId, list[PeerId]], None] | None = None,
        alive: Callable[[PeerId], bool] | None = None,
        on_applied: AppliedHook | None = None,
    ) -> None:
        self.me, self.store, self.rpc, self.states = me, store, rpc, states
        self._alive, self._on_members, self.compact_after = alive, on_members, compact_after
        self.mail = RaftMail(rpc, address, peers)
        done = self._members_changed  # deferred while a snapshot is being installed
        self.applier = GroupApplier(store, states, apply, on_applied, self._halt, done)
        self.disk = ReadyDisk(store, self._saved, self._halt)
        self._options = replace(options or RaftOptions(), quiesce=alive is not None)
        self._rng = random.Random(seed)
        self._on_change = on_change or (lambda: None)
        self._groups: dict[ChunkId, GroupState] = {}
        self._reads = 0  # ReadIndex contexts issued
        self._ticker: asyncio.Task[None] | None = None
        rpc.register(RaftBatch, self.rpc_raft_batch)

    def start(self, tick: float = TICK_SECONDS) -> None:
        """Start ticking every group (on the running loop)."""
        self._ticker = asyncio.get_running_loop().create_task(self._tick_forever(tick))

    async def close(self) -> None:
        """Stop ticking; proposals still waiting fail with `PeerUnavailable`."""
        if self._ticker is not None:
            self._ticker.cancel()
            await asyncio.gather(self._ticker, return_exceptions=True)
            self._ticker = None
        await self.disk.close()
        await self.applier.close()
        for group in self._groups.values():
            group.fail_all(PeerUnavailable("this peer is closing"))

    def found(self, chunk: ChunkId, voters: Iterable[PeerId]) -> None:
        """Found the chunk's group with these voters (every founding member calls
        this with the same voters; a group of one leads at once).

        Raises:
            ValueError: this peer already has the chunk's group.
        """
        if chunk in self._groups or self.store.raft_applied_index(chunk) is not None:
            raise ValueError(f"chunk {chunk} already has a Raft group here")
        config = Config(frozenset(node_id(p) for p in voters))
        boot = PersistentState.bootstrap(config)
        self._open(chunk, boot, applied=1)
        persist_founding(self.store, chunk, boot)
        if self.states is not None and self.states.knows(chunk):
            # The log starts from a snapshot of the chunk (its table, and any history
            # from before the group) that every joiner receives: taken in a worker
            # (`GroupMembers` takes no one in before: `applier.idle`).
            self.applier.compact(self._groups[chunk], 1)
        if config.voters == {node_id(self.me)}:
            self._groups[chunk].node.campaign()
            self._process(self._groups[chunk])
            self._flush()

    def resume(self, chunk: ChunkId) -> bool:
        """Reopen the chunk's group from the store after a restart; False if this
        peer persisted none (it joins the group empty with `join`)."""
        if (kept := self.store.raft_load(chunk)) is None:
            return False
        self._open(chunk, state_of(kept), applied=kept.applied)
        return True

    async def join(self, chunk: ChunkId) -> None:
        """Take part in a group as a new, empty member (the leader sends the log); a
        worker stores its empty state unless one is kept (the loop must not wait)."""
        await off_loop(self.store, self.store.raft_save, chunk)  # creates none if kept
        if chunk not in self._groups:  # not opened by another join meanwhile
            self._open(chunk, PersistentState(), applied=0)

    def trust(self, chunk: ChunkId, members: Iterable[PeerId]) -> None:
        """Hear these peers in the chunk's group (its members, as its leader just said)."""
        self._group(chunk).trusted = frozenset(node_id(p) for p in members)

    def _open(self, chunk: ChunkId, state: PersistentState, applied: int) -> None:
        rng = random.Random(self._rng.getrandbits(64))
        node = RaftNode(node_id(self.me), state, rng, self._options, applied=applied)
        self._groups[chunk] = GroupState(chunk, node)

    def leader(self, chunk: ChunkId) -> PeerId | None:
        """The chunk's leader as this peer knows it, or None during an election."""
        group = self._groups.get(chunk)
        return None if group is None else self._peer(group.leader)

    def quiet(self, chunk: ChunkId) -> bool:
        """Whether the chunk's group here is quiet: idle, its leader sends nothing."""
        return self._group(chunk).node.quiet

    def is_leader(self, chunk: ChunkId) -> bool:
        """Whether this peer leads the chunk's group now."""
        group = self._groups.get(chunk)
        return group is not None and group.role is Role.LEADER

    def led(self) -> list[ChunkId]:
        """The chunks whose group this peer leads now."""
        return [c for c, g in self._groups.items() if g.role is Role.LEADER]

    def members(self, chunk: ChunkId) -> list[PeerId]:
        """The other members of the chunk's group (voters, learners) named here."""
        group = self._group(chunk)
        peers = (self._peer(n) for n in group.node.config.members if n != node_id(self.me))
        return [p for p in peers if p is not None]

    def news_age(self) -> dict[ChunkId, float]:
        """Seconds since each group here last heard from its leader (0: this peer leads)."""
        now = time.monotonic()
        return {c: 0.0 if g.role is Role.LEADER else now - g.heard for c, g in self._groups.items()}

    def promotable(self, chunk: ChunkId) -> frozenset[int]:
        """The learners `voters.next_change` may promote: caught up, as the leader knows."""
        return self._group(chunk).node.caught_up_learners()

    def member_back(self, peer: PeerId) -> None:
        """`peer` (re)joined: wake its groups, and report their members again."""
        for group in [g for g in self._groups.values() if node_id(peer) in g.node.config.members]:
            group.node.wake()  # it knows no leader until one heartbeats
            group.members = frozenset()  # it can be named now
            if self.applier.idle(group.chunk):
                self._members_changed(group)

    def applied(self, chunk: ChunkId) -> int:
        """The last log index applied to this peer's store."""
        return self.store.raft_applied_index(chunk) or 0

    async def propose(
        self,
        chunk: ChunkId,
        data: bytes,
        timeout: float = PROPOSE_TIMEOUT,  # noqa: ASYNC109
    ) -> Applied:
        """Append `data` to the chunk's log here (this peer must lead) and wait
        until it is committed and applied here; returns what applying it did.

        Raises:
            NotChunkLeader: another peer leads, or none does yet.
            ProposalLost: a new leader overwrote the entry before it committed.
            RequestTimeout: not committed within `timeout` (no quorum reachable).
        """
        group = self._group(chunk)
        return await self._await_entry(group, lambda: group.node.propose(data), timeout)

    def config(self, chunk: ChunkId) -> Config:
        """The chunk's group configuration as this peer holds it now."""
        return self._group(chunk).node.config

    async def propose_change(
        self,
        chunk: ChunkId,
        change: ConfChange,
        timeout: float = PROPOSE_TIMEOUT,  # noqa: ASYNC109
    ) -> Applied:
        """Append a single-server membership change (as leader); wait until it applies.

        Raises:
            NotChunkLeader: another peer leads, or none does yet.
            ProposalRefused: a change is still uncommitted, or this new leader's
                first entry is (retry after `progressed`).
            RequestTimeout: not committed within `timeout`.
        """
        group = self._group(chunk)
        return await self._await_entry(
            group, partial(group.node.propose_conf_change, change), timeout
        )

    async def progressed(self, chunk: ChunkId) -> None:
        """Until something next happens in the chunk's group here (callers re-check)."""
        group = self._group(chunk)
        group.progress.clear()
        await group.progress.wait()

    def drop(self, chunk: ChunkId) -> None:
        """Forget the chunk's group here (left): its node, waiters and persisted state."""
        group = self._groups.pop(chunk, None)
        self.applier.forget(chunk)
        if group is not None:
            group.fail_all(PeerUnavailable(f"this peer left chunk {chunk.short}"))
        self.disk.then(chunk, partial(self.store.raft_drop, chunk))  # after a write under way

    async def catch_up(self, chunk: ChunkId, timeout: float = PROPOSE_TIMEOUT) -> int:  # noqa: ASYNC109
        """Wait until this replica has applied everything the chunk's group had
        committed when asked (ReadIndex, thesis §6.4), so a view begun now sees
        every acknowledged commit; returns the applied index.

        Raises:
            NotChunkLeader: no leader is known (an election; retry).
            RequestTimeout: the leader could not confirm within `timeout`.
        """
        group = self._group(chunk)
        self._reads += 1
        context = self.me.to_bytes() + self._reads.to_bytes(8, "big")
        try:
            reading = group.read(context)
        except NotLeader as exc:
            raise NotChunkLeader.of(chunk, self._peer(exc.leader)) from None
        self._process(group)
        self._flush()
        return await reading(partial(self.applied, chunk), timeout)

    async def _await_entry(
        self,
        group: GroupState,
        start: Callable[[], tuple[int, int]],
        timeout: float,  # noqa: ASYNC109
    ) -> Applied:
        """Start a proposal (`start` gives its index and term); wait until it applies here."""
        try:
            index, term = start()
        except NotLeader as exc:
            raise NotChunkLeader.of(group.chunk, self._peer(exc.leader)) from None
        done: asyncio.Future[Applied] = asyncio.get_running_loop().create_future()
        group.waiting[index] = (term, done)
        self._process(group)
        self._flush()
        return await group.applied(index, done, timeout, self._peer)

    def _group(self, chunk: ChunkId) -> GroupState:
        if (group := self._groups.get(chunk)) is None:
            raise NotChunkLeader.of(chunk, None)
        return group

    # -- the Ready loop ----------------------------------------------------------------
    async def _tick_forever(self, tick: float) -> None:
        while True:
            await asyncio.sleep(tick)
            for group in list(self._groups.values()):
                leader = self._peer(group.leader)  # a quiet follower asks after it
                group.node.tick(self._alive is None or leader is None or self._alive(leader))
                with contextlib.suppress(CorruptRepoError):  # halted: logged, and gone
                    self._process(group)
            self._flush()

    def rpc_raft_batch(self, req: Request) -> Ack:
        """Step every message of a batch into its group (`group_state.step_batch`),
        then run their Ready loops; a batch sent as a request gets an `Ack`."""
        body: RaftBatch = req.body
        for group in step_batch(self._groups, node_id(self.me), req.sender, body.messages):
            self._process(group)
            group.progress.set()
        self._flush()
        return Ack()

    def _process(self, group: GroupState) -> None:
        """Run one group's Ready loop until it has nothing to do; halt it if one fails."""
        try:
            self._ready_loop(group)
        except Exception as exc:
            raise self._halt(group, exc) from exc

    def _halt(self, group: GroupState, error: Exception) -> CorruptRepoError:
        self._groups.pop(group.chunk, None)  # and `halted` fails its waiters
        return halted(group, error)

    def _ready_loop(self, group: GroupState) -> None:
        while not self.disk.busy(group.chunk) and group.node.has_ready():
            rd = group.node.ready()
            if self.disk.save(group, rd):  # else a worker writes it, and `_saved` goes on
                self._handle(group, rd)

    def _saved(self, group: GroupState, rd: Ready) -> None:
        """A Ready a worker wrote: handle it, and the group's next ones."""
        if self._groups.get(group.chunk) is not group:
            return  # left or halted meanwhile
        with contextlib.suppress(CorruptRepoError):  # halted: logged, and gone
            try:
                self._handle(group, rd)
            except Exception as exc:
                raise self._halt(group, exc) from exc
            self._process(group)
        self._flush()

    def _handle(self, group: GroupState, rd: Ready) -> None:
        """Send, apply and advance a persisted Ready."""
        for message in rd.messages:
            self.mail.post(group.chunk, message)
        snap = None if rd.snapshot is None else (rd.snapshot.data, rd.snapshot.index)
        self.applier.hand(group, rd.committed_entries, snap)
        for read in rd.read_states:
            waiting = group.reads.get(read.context)
            if waiting is not None and not waiting.done():
                waiting.set_result(read.index)
        if (rd.role, rd.leader) != (group.role, group.leader):
            group.new_leader(rd.role, rd.leader, NotChunkLeader.of(group.chunk, None))
            log.debug("chunk %s: %s, leader %s", group.chunk.short, rd.role.name, rd.leader)
            self._on_change()
        group.node.advance(rd)
        if self.applier.idle(group.chunk):  # else once applied: a snapshot makes the chunk
            self._members_changed(group)
        if group.node.log.applied - group.node.log.snapshot.index >= self.compact_after:
            self.applier.compact(group, group.node.log.applied)

    def _members_changed(self, group: GroupState) -> None:
        """Report the group's members if they changed (the store's holders follow)."""
        if self._on_members is not None and group.node.config.members != group.members:
            group.members = group.node.config.members
            self._on_members(group.chunk, self.mail.peers(group.members))

    def _flush(self) -> None:
        """Send what every group queued (waiters re-check if anything left)."""
        if self.mail.flush():
            self._on_change()

    def _peer(self, node: int) -> PeerId | None:
        return self.mail.peer(node)
