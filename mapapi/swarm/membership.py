"""Who is in the swarm: members by id, with their addresses and when last heard of."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

from mapapi.core.errors import PeerUnavailable
from mapapi.core.ids import PeerId
from mapapi.net.messages import Member


@dataclass
class MemberState:
    """A member plus when a message from it last arrived (monotonic seconds)."""

    member: Member
    last_seen: float | None = None


def label(peer: PeerId, member: Member | None) -> str:
    """See `Members.label`; a name equal to the short id (the default) is not repeated."""
    name = member.name if member is not None else ""
    return f"{name} ({peer.short})" if name and name != peer.short else peer.short


class Members:
    """The peers this peer knows, itself included."""

    def __init__(self, me: Member) -> None:
        self.me = me
        self._known: dict[PeerId, MemberState] = {me.id: MemberState(me, time.monotonic())}
        # Members that said goodbye (stopped): no longer listed, but still named and
        # remembered, as they stay members of their chunks' groups (DESIGN §13).
        self._left: dict[PeerId, Member] = {}
        self.on_added: Callable[[PeerId], None] = lambda peer: None  # told of every `add`

    def add(self, member: Member) -> bool:
        """Learn (or update) a member; returns True if it was new."""
        self._left.pop(member.id, None)
        state = self._known.get(member.id)
        if state is None:
            self._known[member.id] = MemberState(member)
        else:
            state.member = member
        self.on_added(member.id)
        return state is None

    def remove(self, peer: PeerId) -> None:
        """A member left (stopped, saying goodbye): no longer listed, but still
        named and reached by `get` and `address`, and in `departed`."""
        if peer != self.me.id and (state := self._known.pop(peer, None)) is not None:
            self._left[peer] = state.member

    def departed(self) -> list[Member]:
        """The members that said goodbye and did not come back, in id order."""
        return [m for _, m in sorted(self._left.items())]

    def touch(self, peer: PeerId) -> None:
        """Note that a message from `peer` just arrived."""
        state = self._known.get(peer)
        if state is not None:
            state.last_seen = time.monotonic()

    def address(self, peer: PeerId) -> str:
        """Where to reach `peer`.

        Raises:
            PeerUnavailable: the peer is not (or no longer) a known member.
        """
        member = self.get(peer)
        if member is None:
            raise PeerUnavailable(
                f"peer {peer.short} is not a known member of the swarm",
                advice="act: join its swarm first (`mapctl join ADDR`)",
            )
        return member.address

    def label(self, peer: PeerId) -> str:
        """How messages name `peer`: "robot2 (146ca670)" (its name, from `init
        --name`, then its short id), or the short id while the name is unknown."""
        return label(peer, self.get(peer))

    def get(self, peer: PeerId) -> Member | None:
        """A member by id (one that left too), or None."""
        state = self._known.get(peer)
        return state.member if state else self._left.get(peer)

    def all(self) -> list[Member]:
        """Every member, this peer included, in id order."""
        return [s.member for _, s in sorted(self._known.items())]

    def others(self) -> list[MemberState]:
        """Every other member with its last-seen time, in id order."""
        return [s for p, s in sorted(self._known.items()) if p != self.me.id]
