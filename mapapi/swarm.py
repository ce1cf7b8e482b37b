"""`Swarm`: the networked side of a peer: transport, membership, locks, replication.

It owns the RPC endpoint and every task behind it; `Peer.start()` creates it
and `Peer.close()` closes it. Membership is simple: a joiner says Hello to any
member, learns every member from the Welcome, and says Hello to each of them;
a graceful leave says Bye to all (DESIGN §6).
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable

from mapapi.clock import LamportClock
from mapapi.errors import JoinRefused, MapError
from mapapi.history import CommitRecord, Revision
from mapapi.ids import PeerId
from mapapi.lock_client import LockService
from mapapi.membership import Members
from mapapi.net.codec import Ping, Pong
from mapapi.net.messages import Ack, Bye, Hello, Member, Welcome
from mapapi.net.rpc import Request, Rpc
from mapapi.net.shaping import Shaper
from mapapi.net.transport import ZmqTransport
from mapapi.replication import Replicator
from mapapi.store.base import ReplicaStore

log = logging.getLogger(__name__)


class Swarm:
    """Networking for one peer (see the module docstring)."""

    def __init__(
        self,
        peer_id: PeerId,
        name: str,
        store: ReplicaStore,
        clock: LamportClock,
        *,
        lease: float = 5.0,
        shaper: Shaper | None = None,
        on_applied: Callable[[CommitRecord, list[Revision]], None] | None = None,
    ) -> None:
        self.rpc = Rpc(ZmqTransport(peer_id, clock, shaper=shaper))
        self._name = name
        self._peer_id = peer_id
        self.members = Members(Member(peer_id, "", name))
        self.locks = LockService(self.rpc, self.members, lease=lease)
        self.replicator = Replicator(self.rpc, self.members, self.locks, store, on_applied)
        self.locks.admit = self.replicator.admit
        self.rpc.register(Hello, self.rpc_hello)
        self.rpc.register(Bye, self.rpc_bye)
        self.rpc.register(Ping, lambda req: Pong(req.body.payload))
        self.rpc.on_seen = self.members.touch

    @property
    def address(self) -> str:
        """The endpoint other peers reach this one at."""
        return self.members.me.address or self.rpc.address

    async def start(self, listen: str) -> str:
        """Listen on `listen` (port 0 picks a free port); returns the real address."""
        address = await self.rpc.start(listen)
        self.advertise(address)
        return address

    def advertise(self, address: str) -> None:
        """Tell other peers `address` instead of the bound one (before joining):
        a wildcard host such as tcp://0.0.0.0:7000 is no address they can reach."""
        self.members.me = Member(self._peer_id, address, self._name)
        self.members.add(self.members.me)

    # -- membership ------------------------------------------------------------------
    def rpc_hello(self, req: Request) -> Welcome:
        """A peer introduces itself: remember it and tell it every member."""
        member: Member = req.body.member
        if member.id != req.sender or not member.address:
            raise JoinRefused("Hello must carry the sender's own id and address")
        self.members.add(member)
        self.members.touch(member.id)
        return Welcome(tuple(self.members.all()))

    def rpc_bye(self, req: Request) -> Ack:
        """A peer leaves the swarm gracefully."""
        self.members.remove(req.sender)
        return Ack()

    async def join(self, seed: str) -> list[Member]:
        """Join the swarm through the member at `seed`; returns every member.

        Raises:
            JoinRefused: the seed refused, or answered like no mapapi peer.
            NetworkError: the seed did not answer in time.
        """
        hello = Hello(self.members.me)
        try:
            welcome = await self.rpc.request(seed, hello, expect=Welcome)
        except MapError:
            await self.rpc.forget(seed)  # no reconnecting socket left behind
            raise
        if not any(m.address == seed or m.id != self._peer_id for m in welcome.members):
            raise JoinRefused(f"{seed} answered with no members")
        fresh = [m for m in welcome.members if m.id != self._peer_id and self.members.add(m)]
        results = await asyncio.gather(
            *(self.rpc.request(m.address, hello, expect=Welcome) for m in fresh),
            return_exceptions=True,
        )
        for member, result in zip(fresh, results, strict=True):
            if isinstance(result, MapError):
                log.warning("member %s at %s did not answer: %s", member.id, member.address, result)
            elif isinstance(result, Welcome):
                for other in result.members:
                    if other.id != self._peer_id:
                        self.members.add(other)
        return self.members.all()

    async def leave(self) -> None:
        """Say Bye to every other member (best effort, short deadline)."""
        await asyncio.gather(
            *(
                self.rpc.request(s.member.address, Bye(), timeout=1.0)
                for s in self.members.others()
            ),
            return_exceptions=True,
        )

    async def close(self) -> None:
        """Stop renewals and close the endpoint (fails pending requests)."""
        await self.locks.close()
        await self.rpc.close()
