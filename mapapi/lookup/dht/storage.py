"""The soft-state values one Chord node stores (DESIGN §7), pure: time is an argument.

A key maps to a set of members, each with an expiry time. `add` and `remove`
change one member in place, so concurrent writers never lose each other's
members (no read-modify-write over the network); a member whose owner stops
re-adding it disappears when its time-to-live runs out.

Anyone on the ring may add, so what a node keeps for others is bounded: each
member by `limits.MAX_BYTES["member"]`, each time-to-live by `limits.MAX_TTL`,
and all members together by a byte budget (`limits.MAX_NODE_STORAGE_BYTES`);
beyond it a node refuses new members until old ones expire.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator

from mapapi.core import limits
from mapapi.core.errors import LimitExceeded

_OVERHEAD = 64  # bytes counted per member on top of its own (key, expiry, dict slot)


class Storage:
    """Members per ring key, each until its expiry (seconds on the caller's clock).

    Args:
        capacity: the byte budget of all members (see the module docstring).
    """

    def __init__(self, capacity: int = limits.MAX_NODE_STORAGE_BYTES) -> None:
        self._data: dict[int, dict[bytes, float]] = {}
        self.capacity = capacity
        self.used = 0  # bytes counted against `capacity`

    def __len__(self) -> int:
        return sum(len(members) for members in self._data.values())

    def add(self, key: int, member: bytes, ttl: float, now: float) -> None:
        """Add `member` under `key` until ``now + ttl`` (a refresh never shortens it).

        Raises:
            LimitExceeded: `ttl` is not in (0, MAX_TTL], the member is too large,
                or the node's budget is spent (all are ValueErrors too).
        """
        limits.ttl(ttl)
        limits.size("member", member)
        members = self._data.setdefault(key, {})
        old = members.get(member)
        if old is None:
            cost = len(member) + _OVERHEAD
            if self.used + cost > self.capacity:
                if not members:
                    del self._data[key]
                raise LimitExceeded(
                    f"this node stores {self.used} bytes for others, its limit is "
                    f"{self.capacity} (MAX_NODE_STORAGE_BYTES); try again once entries expire"
                )
            self.used += cost
            old = 0.0
        members[member] = max(old, now + ttl)

    def remove(self, key: int, member: bytes) -> bool:
        """Remove `member` from `key`; returns whether it was there."""
        members = self._data.get(key)
        if members is None or member not in members:
            return False
        del members[member]
        self.used -= len(member) + _OVERHEAD
        if not members:
            del self._data[key]
        return True

    def get(self, key: int, now: float) -> set[bytes]:
        """The members of `key` that have not expired at `now`."""
        return {m for m, expiry in self._data.get(key, {}).items() if expiry > now}

    def expire(self, now: float) -> int:
        """Drop every member expired at `now`; returns how many."""
        dropped = 0
        for key in list(self._data):
            members = self._data[key]
            for member in [m for m, expiry in members.items() if expiry <= now]:
                del members[member]
                self.used -= len(member) + _OVERHEAD
                dropped += 1
            if not members:
                del self._data[key]
        return dropped

    def entries(
        self, now: float, where: Callable[[int], bool] = lambda _key: True
    ) -> Iterator[tuple[int, bytes, float]]:
        """``(key, member, seconds left)`` of the live members whose key passes `where`."""
        for key, members in self._data.items():
            if where(key):
                for member, expiry in members.items():
                    if expiry > now:
                        yield key, member, expiry - now
