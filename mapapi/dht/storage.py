"""The soft-state values one Chord node stores (DESIGN §7), pure: time is an argument.

A key maps to a set of members, each with an expiry time. `add` and `remove`
change one member in place, so concurrent writers never lose each other's
members (no read-modify-write over the network); a member whose owner stops
re-adding it disappears when its time-to-live runs out.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator


class Storage:
    """Members per ring key, each until its expiry (seconds on the caller's clock)."""

    def __init__(self) -> None:
        self._data: dict[int, dict[bytes, float]] = {}

    def __len__(self) -> int:
        return sum(len(members) for members in self._data.values())

    def add(self, key: int, member: bytes, ttl: float, now: float) -> None:
        """Add `member` under `key` until ``now + ttl`` (a refresh never shortens it).

        Raises:
            ValueError: `ttl` is not positive.
        """
        if not ttl > 0:
            raise ValueError(f"a time-to-live is a positive number of seconds, got {ttl!r}")
        members = self._data.setdefault(key, {})
        members[member] = max(members.get(member, 0.0), now + ttl)

    def remove(self, key: int, member: bytes) -> bool:
        """Remove `member` from `key`; returns whether it was there."""
        members = self._data.get(key)
        if members is None or member not in members:
            return False
        del members[member]
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
