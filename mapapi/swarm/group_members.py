"""Holders come and go through the chunk's log (DESIGN §13): joining, leaving, and
the removal of a dead holder are membership changes the chunk's leader proposes,
never a peer's own decision about the others.

`change_members` drives `voters.next_change` through the log one single-server
change at a time (an odd number of voters, at most the replication factor; the
other holders learners). `GroupMembers` serves `GroupJoin` and `GroupLeave` (a
member that does not lead answers with the leader to ask), lets
this peer join a chunk's group from any member's address and wait until the
leader's snapshot or log brought its replica up to the change, leave one, and,
as the leader, removes members that liveness has declared dead for a while.

A member removed while it was away (dead to the others for `remove_after`)
hears nothing from its group any more, and its own messages are dropped: only
members speak. So a peer whose group has known no leader for `STUCK_AFTER`, or
has not heard the leader it knows for as long while the group is not quiet (a
removed learner: it never campaigns, so it keeps that leader), asks to join
again, through a member that answers (`rejoin_stuck`); so does every group of a
peer that itself stood still for the removal delay. The leader
answers a member with nothing new, and takes one it had removed in again as a
learner (`GroupChanged.added`); either way the peer now hears the members the
answer names, the leader among them (it may have missed the change that added
that leader). It keeps its log: the leader probes it as any lagging follower's,
and Raft's log matching replaces an uncommitted tail (wiping it instead would
let the leader believe the peer holds entries it dropped).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Callable, Iterable

from mapapi.core.errors import (
    ChunkNotFound,
    CorruptRepoError,
    MapError,
    NotChunkLeader,
    RequestTimeout,
)
from mapapi.core.ids import ChunkId, PeerId
from mapapi.net.codec import Ping, Pong
from mapapi.net.messages import GroupChanged, GroupJoin, GroupLeave
from mapapi.net.rpc import Request, Rpc
from mapapi.store.offload import off_loop
from mapapi.swarm.chain_check import refuse_to_hand_on
from mapapi.swarm.failure import REMOVE_AFTER
from mapapi.swarm.group_state import AddressFn
from mapapi.swarm.groups import PROPOSE_TIMEOUT, RaftGroups
from mapapi.swarm.raft_types import ConfChange, ConfChangeKind, Config, ProposalRefused
from mapapi.swarm.raft_wire import node_id
from mapapi.swarm.voters import DEFAULT_REPLICATION, next_change

log = logging.getLogger(__name__)

CATCH_UP_WAIT = 2.0
"""Seconds a membership change waits for a learner to catch up before it leaves its
promotion to a later round (`GroupMembers.reap`)."""
STUCK_AFTER = 5.0
"""Seconds a group here may know no leader before this peer asks whether it is
still a member (`GroupMembers.rejoin_stuck`)."""
PROBE_TIMEOUT = 2.0
"""Seconds a joiner has to answer the leader's ping before it is taken in."""
ELECTION_PAUSE = 0.05
"""Seconds before asking again a member that knows no leader (an election runs)."""


async def change_members(
    groups: RaftGroups,
    chunk: ChunkId,
    holders: Iterable[PeerId],
    factor: int = DEFAULT_REPLICATION,
    timeout: float = PROPOSE_TIMEOUT,  # noqa: ASYNC109
) -> Config:
    """As the chunk's leader, make `holders` the group's members, one single-server
    change at a time, with the voters `voters.next_change` picks (an odd number,
    at most `factor`); returns the configuration then. A new holder must have
    called `RaftGroups.join` to take in the log. A learner to promote is waited
    for `CATCH_UP_WAIT` seconds at most (a live joiner catches up in a round trip);
    one that lags longer is promoted by a later `reap`, once caught up.

    Raises:
        NotChunkLeader: this peer does not lead the chunk (or stopped leading).
        RequestTimeout: the changes did not all apply within `timeout`.
    """
    return await change_nodes(groups, chunk, {node_id(p) for p in holders}, factor, timeout)


async def change_nodes(
    groups: RaftGroups,
    chunk: ChunkId,
    wanted: set[int],
    factor: int = DEFAULT_REPLICATION,
    timeout: float = PROPOSE_TIMEOUT,  # noqa: ASYNC109
) -> Config:
    """`change_members` by node ids: the members wanted, whether this peer can name
    them (reach them) or not."""
    me = node_id(groups.me)
    while not groups.applier.idle(chunk):  # a joiner gets the founding snapshot, once taken
        await groups.progressed(chunk)
    loop = asyncio.get_running_loop()
    patience = loop.time() + CATCH_UP_WAIT
    try:
        async with asyncio.timeout(timeout):
            while next_change(groups.config(chunk), wanted, factor, me) is not None:
                ready = groups.promotable(chunk)
                change = next_change(groups.config(chunk), wanted, factor, me, ready)
                if change is None:  # a learner to promote has not caught up yet
                    if loop.time() >= patience:
                        break
                    with contextlib.suppress(TimeoutError):
                        async with asyncio.timeout_at(patience):
                            await groups.progressed(chunk)
                    continue
                try:
                    await groups.propose_change(chunk, change, timeout)
                except ProposalRefused:  # its own first entry, or a change still uncommitted
                    await groups.progressed(chunk)
    except TimeoutError:
        raise RequestTimeout(
            f"chunk {chunk.short}: its members did not change within {timeout:g} s "
            "(too few voters reachable)"
        ) from None
    return groups.config(chunk)


def roles(groups: RaftGroups, chunk: ChunkId, holders: Iterable[PeerId]) -> dict[PeerId, str]:
    """Each holder's role in the chunk's group as this member knows it: "leader",
    "voter" or "learner" (a holder the configuration does not name yet: "joining")."""
    config, leader = groups.config(chunk), groups.leader(chunk)

    def role(peer: PeerId) -> str:
        if peer == leader:
            return "leader"
        node = node_id(peer)
        if node in config.voters:
            return "voter"
        return "learner" if node in config.members else "joining"

    return {p: role(p) for p in holders}


class GroupMembers:
    """Joining and leaving chunks' groups, and removing dead members (see the module
    docstring).

    Args:
        groups: this peer's Raft groups.
        rpc: serves and sends `GroupJoin` and `GroupLeave`.
        address: where a peer is reached now.
        factor: the replication factor of a chunk that sets none (voters at most).
        remove_after: seconds a member stays declared dead before the leader
            removes it (`reap`).
    """

    def __init__(
        self,
        groups: RaftGroups,
        rpc: Rpc,
        address: AddressFn,
        factor: int = DEFAULT_REPLICATION,
        remove_after: float = REMOVE_AFTER,
    ) -> None:
        self.groups = groups
        self.rpc = rpc
        self._address = address
        self.default_factor = factor
        self.remove_after = remove_after
        self._dead_since: dict[PeerId, float] = {}
        self._changing: dict[ChunkId, asyncio.Lock] = {}  # one membership change at a time
        self._leaderless: dict[ChunkId, float] = {}  # since when a group here knows none
        self._tried: dict[ChunkId, float] = {}  # when this peer last asked to join again
        self._round: float | None = None  # when `rejoin_stuck` last ran
        rpc.register(GroupJoin, self.rpc_group_join)
        rpc.register(GroupLeave, self.rpc_group_leave)

    def factor(self, chunk: ChunkId) -> int:
        """The chunk's replication factor: its own (`Store.replication`), else the default."""
        try:
            return self.groups.store.replication(chunk) or self.default_factor
        except ChunkNotFound:  # not held here (yet)
            return self.default_factor

    async def join(
        self,
        chunk: ChunkId,
        via: PeerId,
        timeout: float = PROPOSE_TIMEOUT,  # noqa: ASYNC109
    ) -> GroupChanged:
        """Become a holder of `chunk` through its member `via`, and wait until this
        replica applied the change that added it (its state arrived with it).

        Raises:
            RequestTimeout: the change, or the state, did not arrive in time (this
                peer stays in the group: its state may still arrive).
            CorruptRepoError: the leader's replica no longer matches its hash chain
                (it hands it on to no one; this peer is not taken in).
            NetworkError: `via` could not be reached.
        """
        joined = self.groups.store.raft_applied_index(chunk) is None
        if joined:
            await self.groups.join(chunk)
        try:
            async with asyncio.timeout(timeout):
                changed = await self._ask(via, GroupJoin(chunk))
                while self.groups.applied(chunk) < changed.index:
                    await self.groups.progressed(chunk)
        except CorruptRepoError:
            if joined:  # refused outright: not taken in
                self.groups.drop(chunk)
            raise
        except TimeoutError:
            # The leader may have taken us in already: a member keeps its log (it
            # must not come back empty), and its state arrives later.
            raise RequestTimeout(
                f"chunk {chunk.short}: its state did not arrive within {timeout:g} s"
            ) from None
        return changed

    async def leave(self, chunk: ChunkId, timeout: float = PROPOSE_TIMEOUT) -> None:  # noqa: ASYNC109
        """Stop holding `chunk`: its group lets this peer go, then it forgets it.

        Raises:
            NotChunkLeader: the group is electing a leader (retry).
            RequestTimeout, NetworkError: the leader could not be reached.
        """
        leader = self.groups.leader(chunk)
        if leader is None:
            raise NotChunkLeader.of(chunk, None)
        if leader != self.groups.me:
            async with asyncio.timeout(timeout):
                await self._ask(leader, GroupLeave(chunk))
        else:  # remove itself, and step down: the next leader rebalances the voters (`reap`)
            me = ConfChange(ConfChangeKind.REMOVE_NODE, node_id(self.groups.me))
            await self.groups.propose_change(chunk, me, timeout)
        self.groups.drop(chunk)

    async def _ask(self, member: PeerId, body: GroupJoin | GroupLeave) -> GroupChanged:
        """Ask `member`, then the leader it names, until a leader answers (within the
        caller's deadline; a member that knows no leader is asked again shortly)."""
        while True:
            changed: GroupChanged = await self.rpc.request(
                self._address(member), body, expect=GroupChanged
            )
            if changed.index:
                return changed
            if changed.leader is not None:
                member = changed.leader
            else:
                await asyncio.sleep(ELECTION_PAUSE)

    async def rpc_group_join(self, req: Request) -> GroupChanged:
        """Take the sender in as a holder of the chunk (as its leader, or through it)."""
        body: GroupJoin = req.body
        return await self._change(body.chunk, add=req.sender)

    async def rpc_group_leave(self, req: Request) -> GroupChanged:
        """Let the sender go from the chunk's group (as its leader, or through it)."""
        body: GroupLeave = req.body
        return await self._change(body.chunk, drop=req.sender)

    async def _change(
        self, chunk: ChunkId, add: PeerId | None = None, drop: PeerId | None = None
    ) -> GroupChanged:
        groups = self.groups
        if not groups.is_leader(chunk):
            return GroupChanged(0, (), groups.leader(chunk))  # ask the leader
        if add is not None and add not in groups.members(chunk):
            await refuse_to_hand_on(groups.store, chunk, groups.me)
            # A joiner must be reachable where the swarm knows it, and be the one that
            # answers there: a stranger (or one claiming another peer's address, as an
            # open swarm's hostile host may) taken in would cost the quorum.
            address = self._address(add)
            await self.rpc.request(address, Ping(), timeout=PROBE_TIMEOUT, expect=Pong, sender=add)
        # One change of a chunk's members at a time, each from the members then: two
        # joins computed side by side would each take the other out again.
        async with self._changing.setdefault(chunk, asyncio.Lock()):
            # from the configuration, not the members this peer can name: a member
            # that said goodbye (stopped) is still one, until it leaves or dies
            before = groups.config(chunk).members
            wanted = set(before) | ({node_id(add)} if add else set())
            wanted -= {node_id(drop)} if drop else set()
            config = await change_nodes(groups, chunk, wanted, self.factor(chunk))
        members = tuple(sorted(groups.mail.peers(config.members)))
        added = add is not None and node_id(add) not in before
        return GroupChanged(groups.applied(chunk), members, added=added)

    async def rejoin_stuck(self, answers: Callable[[PeerId], bool], now: float) -> list[ChunkId]:
        """Ask to join again, through a member `answers` says answers, each group here
        that looks cut off from its leader (`_cut_off`, by `now`, monotonic; one try
        per `STUCK_AFTER`), and every group after this process stood still for
        `remove_after` (paused or blocked: meanwhile its groups may have gone quiet
        and removed it). See the module docstring; returns the chunks joined again."""
        paused = self._round is not None and now - self._round >= self.remove_after
        self._round = now
        back: list[ChunkId] = []
        silent = self.groups.news_age()
        for chunk in self.groups.store.chunk_ids():
            if not (self._cut_off(chunk, silent.get(chunk, 0.0), now) or paused):
                continue
            if now - self._tried.get(chunk, now - STUCK_AFTER) < STUCK_AFTER:
                continue
            self._tried[chunk] = now
            with contextlib.suppress(NotChunkLeader):  # no group here (yet)
                if await self._rejoin(chunk, answers):
                    back.append(chunk)
        return back

    def _cut_off(self, chunk: ChunkId, silent: float, now: float) -> bool:
        """Whether the group has known no leader for `STUCK_AFTER`, or has heard
        nothing for as long from the one it knows while not quiet: a learner removed
        while cut off still knows its leader, which no longer writes to it."""
        if self.groups.leader(chunk) is None:
            return now - self._leaderless.setdefault(chunk, now) >= STUCK_AFTER
        self._leaderless.pop(chunk, None)
        return silent >= STUCK_AFTER and not self.groups.quiet(chunk)

    async def _rejoin(self, chunk: ChunkId, answers: Callable[[PeerId], bool]) -> bool:
        """Ask members that answer, one after the other, until one takes this peer's
        request to the leader; whether the leader had removed it (it is taken in again).
        A member that knows no leader either is passed over at once: a group electing
        one must not hold up this round of every other group's (`_reap`)."""
        body = GroupJoin(chunk)
        for member in [p for p in self.groups.members(chunk) if answers(p)]:
            try:
                changed = await self._ask_once(member, body)
                if not changed.index and changed.leader is not None:
                    changed = await self._ask_once(changed.leader, body)
            except MapError as exc:
                log.debug("chunk %s: %s did not take us in: %s", chunk.short, member.short, exc)
                continue
            if not changed.index:
                continue
            self.groups.trust(chunk, changed.members)  # the leader among them
            if changed.added:
                log.warning("chunk %s: removed while away, taken in again", chunk.short)
            return changed.added
        return False

    async def _ask_once(self, member: PeerId, body: GroupJoin) -> GroupChanged:
        address = self._address(member)
        return await self.rpc.request(address, body, timeout=PROBE_TIMEOUT, expect=GroupChanged)

    async def reap(self, is_dead: Callable[[PeerId], bool], now: float) -> list[PeerId]:
        """As the leader of each chunk, remove the members `is_dead` has said are dead
        for `remove_after` seconds (by `now`, monotonic), and bring the voters back
        to their odd target (after a leader left, say); returns the ones removed.

        A member that comes back before is forgotten from the count.
        """
        removed: set[PeerId] = set()
        led = self.groups.led()
        # Every led chunk's factor read in one worker: a read per chunk on the loop waits
        # for the interpreter lock (up to the switch interval) while a thread computes.
        factors = await off_loop(self.groups.store, lambda: {c: self.factor(c) for c in led})
        for chunk in led:
            members = self.groups.members(chunk)
            dead = [p for p in members if is_dead(p)]
            for peer in dead:
                self._dead_since.setdefault(peer, now)
            gone = [p for p in dead if now - self._dead_since[p] >= self.remove_after]
            config = self.groups.config(chunk)
            # only members declared dead long enough go (one this peer cannot name,
            # say after its goodbye, stays: it is stopped, not gone)
            wanted = set(config.members) - {node_id(p) for p in gone}
            me = node_id(self.groups.me)
            ready = self.groups.promotable(chunk)
            if len(config.voters - {node_id(p) for p in dead}) <= len(config.voters) // 2:
                # no majority would commit the change: proposing it would only
                # shrink this leader's view of the configuration (a change takes
                # effect once appended), and what a minority's errors name
                continue
            if next_change(config, wanted, factors[chunk], me, ready) is None:
                continue  # nothing to do, or only a learner to promote that lags
            try:
                async with self._changing.setdefault(chunk, asyncio.Lock()):
                    await change_nodes(self.groups, chunk, wanted, factors[chunk])
            except (NotChunkLeader, RequestTimeout) as exc:  # the next round tries again
                log.warning("chunk %s: dead members not removed yet: %s", chunk.short, exc)
                continue
            if gone:
                log.warning(
                    "chunk %s: removed dead members %s", chunk.short, [p.short for p in gone]
                )
            removed |= set(gone)
        alive = {p for p in self._dead_since if not is_dead(p)}
        for peer in alive:
            del self._dead_since[peer]
        return sorted(removed)
