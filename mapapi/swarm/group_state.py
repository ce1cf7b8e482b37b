"""One chunk's group as the multi-Raft shell keeps it (DESIGN §13): the node,
what its proposers and readers wait for, and how a `Ready` is persisted.

`RaftGroups` (swarm/groups.py) owns many of these and drives them.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Awaitable, Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from mapapi.core.errors import CorruptRepoError, ProposalLost, RequestTimeout
from mapapi.core.ids import ChunkId, PeerId
from mapapi.store.base import ReplicaStore
from mapapi.swarm.raft import RaftNode
from mapapi.swarm.raft_types import NONE, Entry, PersistentState, Ready, Role
from mapapi.swarm.raft_wire import from_wire, node_id, rows

if TYPE_CHECKING:
    from mapapi.net.messages import RaftMessage

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class Applied:
    """What applying one entry did: the result its proposer receives, and the
    newest commit time it brought to the chunk (0: none)."""

    result: object = None
    time: int = 0


ApplyFn = Callable[[ChunkId, Entry], Applied]
"""Applies one committed NORMAL entry of a chunk's log to the store (called inside
`store.exclusive()`, with the applied index and time recorded in the same
transaction; from any thread: `swarm/group_apply.py`)."""
AddressFn = Callable[[PeerId], str]
"""Where a peer is reached now (the member list); raises `PeerUnavailable`."""


@dataclass
class GroupState:
    """One chunk's node, and the proposals and reads waiting on it."""

    chunk: ChunkId
    node: RaftNode
    waiting: dict[int, tuple[int, asyncio.Future[Applied]]] = field(default_factory=dict)
    role: Role = Role.FOLLOWER
    leader: int = NONE
    progress: asyncio.Event = field(default_factory=asyncio.Event)  # set when entries apply
    reads: dict[bytes, asyncio.Future[int]] = field(default_factory=dict)  # ReadIndex waits
    members: frozenset[int] = frozenset()  # the configuration last reported (`on_members`)
    heard: float = field(default_factory=time.monotonic)  # when its leader last spoke here
    trusted: frozenset[int] = frozenset()  # members named by the leader (`GroupMembers`)

    def settle(self, entries: tuple[Entry, ...], results: dict[int, Applied]) -> None:
        """Answer the proposals of these applied entries: with what applying did,
        or `ProposalLost` where a new leader's entry took the index."""
        for entry in entries:
            waiting = self.waiting.pop(entry.index, None)
            if waiting is None:
                continue
            term, done = waiting
            if done.done():
                continue
            if term == entry.term:
                done.set_result(results.get(entry.index, Applied()))
            else:
                done.set_exception(
                    ProposalLost(f"chunk {self.chunk.short}: entry {entry.index} was replaced")
                )

    def new_leader(self, role: Role, leader: int, error: Exception) -> None:
        """The node's role or leader changed: keep them, and fail every read still
        waiting for a leader's confirmation with `error` (a ReadIndex request dies
        with the leader that took it; the reader asks again, the new one)."""
        self.role, self.leader = role, leader
        for waiting in self.reads.values():
            if not waiting.done():
                waiting.set_exception(error)

    def read(self, context: bytes) -> Callable[[Callable[[], int], float], Awaitable[int]]:
        """Ask the node for a ReadIndex under `context` (raises `NotLeader`); the
        wait for it: until it is confirmed and the store (`applied`) reached it."""
        done: asyncio.Future[int] = asyncio.get_running_loop().create_future()
        self.node.read_index(context)
        self.reads[context] = done

        async def wait(applied: Callable[[], int], timeout: float) -> int:  # noqa: ASYNC109
            try:
                async with asyncio.timeout(timeout):
                    index = await done
                    while applied() < index:
                        self.progress.clear()
                        await self.progress.wait()
                    return index
            except TimeoutError:
                raise RequestTimeout(
                    f"chunk {self.chunk.short}: its leader did not confirm a read within "
                    f"{timeout:g} s"
                ) from None
            finally:
                self.reads.pop(context, None)

        return wait

    async def applied(
        self,
        index: int,
        done: asyncio.Future[Applied],
        timeout: float,  # noqa: ASYNC109
        peer_of: Callable[[int], PeerId | None],
    ) -> Applied:
        """What applying the entry at `index` did, once it did (`done`); the
        error of an entry not committed within `timeout` (`not_committed`)."""
        try:
            async with asyncio.timeout(timeout):
                return await done
        except TimeoutError:
            self.waiting.pop(index, None)
            raise not_committed(self, index, timeout, peer_of) from None

    def fail_all(self, error: Exception) -> None:
        """Fail every proposal still waiting (the peer is closing)."""
        for _, done in self.waiting.values():
            if not done.done():
                done.set_exception(error)
        self.waiting.clear()


def not_committed(
    group: GroupState, index: int, timeout: float, peer_of: Callable[[int], PeerId | None]
) -> RequestTimeout:
    """The error of a proposal whose entry did not commit in time: how many voters
    hold it, and which did not answer (as this peer, the leader, knows)."""
    voters = group.node.config.voters
    lacking = group.node.lacking(index)
    if not lacking:
        why = "this peer stopped leading it" if group.role is not Role.LEADER else "no answer"
        return RequestTimeout(
            f"chunk {group.chunk.short}: entry {index} not committed within {timeout:g} s ({why})"
        )
    names = ", ".join(p.short if (p := peer_of(n)) else f"node {n}" for n in lacking)
    return RequestTimeout(
        f"no quorum for chunk {group.chunk.short}: {len(voters) - len(lacking)} of {len(voters)} "
        f"voters hold entry {index} after {timeout:g} s ({names} did not answer)"
    )


def persist(store: ReplicaStore, chunk: ChunkId, rd: Ready) -> None:
    """Persist what `rd` asks (snapshot, entries, hard state) before its messages leave."""
    if rd.snapshot is None and not rd.entries and rd.hard_state is None:
        return
    hs = rd.hard_state
    snap = rd.snapshot
    store.raft_save(
        chunk,
        hard=None if hs is None else (hs.term, hs.vote, hs.commit),
        entries=rows(rd.entries),
        snapshot=None if snap is None else (snap.index, snap.term, snap.config.encode(), snap.data),
    )


def persist_founding(store: ReplicaStore, chunk: ChunkId, boot: PersistentState) -> None:
    """Persist a founding member's first state: the configuration entry, applied,
    and the chunk's clock at its newest commit (a history from before the group)."""
    store.raft_save(chunk, hard=(1, NONE, 1), entries=rows(boot.entries))
    # the chain's last link is the newest commit (listing the commits scans every row)
    links = store.chain_links(chunk)
    record = store.commit_record(links[-1][0]) if links else None
    store.raft_applied(chunk, 1, 0 if record is None else record.time)


def snapshot_at(group: GroupState, index: int, data: bytes) -> tuple[int, int, bytes, bytes]:
    """The stored form of a snapshot of `data` at an applied `index` of the group's
    log: (index, term, configuration then, data)."""
    log = group.node.log
    term = log.term(index)
    if term is None:
        raise ValueError(f"cannot compact chunk {group.chunk.short} to {index}: not in its log")
    return index, term, log.config_at(index).encode(), data


def persist_compaction(
    store: ReplicaStore, chunk: ChunkId, snap: tuple[int, int, bytes, bytes]
) -> None:
    """Store a snapshot of this replica's own state: it replaces the entries up to
    its index, if newer than the stored snapshot (any thread)."""
    store.raft_save(chunk, snapshot=snap, compacted=True)


def step_batch(
    groups: Mapping[ChunkId, GroupState],
    me: int,
    sender: PeerId,
    messages: Iterable[RaftMessage],
) -> list[GroupState]:
    """Step the messages of one batch from `sender` into their groups here; the
    groups they reached. A message to a group this peer does not have is skipped
    (it may arrive before `join` or after the chunk was dropped), and so is one
    that is not the sender's own, or malformed.

    Only a member of a group, as this peer's configuration knows it, speaks in it:
    Raft trusts its members, and a stranger's append with a higher term would
    otherwise write its entries into the chunk. A peer that has joined and knows
    no configuration yet hears anyone (its leader is not known to it), and one
    that asked to join again hears the members the leader's answer named
    (`trusted`): it may have missed the change that added the current leader.
    """
    node = node_id(sender)
    touched: dict[ChunkId, GroupState] = {}
    for wire in messages:
        group = groups.get(wire.chunk)
        if group is None or wire.to != me:
            continue
        if wire.sender != node:  # a node speaks only for itself
            log.warning("refused a raft message of node %d from %s", wire.sender, sender)
            continue
        members = group.node.config.members
        if members and node not in members and node not in group.trusted:
            log.debug("chunk %s: no member sent %s", wire.chunk.short, sender.short)
            continue
        try:
            message = from_wire(wire)
        except ValueError as exc:
            log.warning("refused a malformed raft message from %s: %s", sender.short, exc)
            continue
        group.node.step(message)
        if group.node.leader == node:
            group.heard = time.monotonic()
        touched[group.chunk] = group
    return list(touched.values())


def halted(group: GroupState, error: Exception) -> CorruptRepoError:
    """The error of a group that stopped because its Ready could not be handled (the
    store refused an entry's effect, say): logged with its cause, and every waiter
    of the group fails with it. Every holder applies the same entries, so going on
    past one would let this replica differ; the group stops here instead, and the
    peer's next start resumes it from what the store holds."""
    log.error("chunk %s: its Raft group stopped here: %r", group.chunk.short, error, exc_info=error)
    halt = CorruptRepoError(
        f"chunk {group.chunk.short}: its Raft group stopped on this peer ({error}); "
        "restart the peer, and run `mapctl fsck` if it stops again"
    )
    group.fail_all(halt)
    return halt


def record_holders(store: ReplicaStore, chunk: ChunkId, peers: list[PeerId]) -> None:
    """Record a group's members as the chunk's holders, unless they are already
    (a write on the loop waits on SQLite's lock while a worker installs a chunk)."""
    if store.holders(chunk) != peers:
        store.set_holders(chunk, peers)
