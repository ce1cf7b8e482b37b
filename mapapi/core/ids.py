"""Typed 128-bit identifiers and 160-bit Chord ring keys."""

from __future__ import annotations

import hashlib
import re
import secrets
from typing import Self

_HEX32 = re.compile(r"[0-9a-f]{32}")


class Id(str):
    """A 128-bit random identifier, written as 32 lowercase hex digits.

    Subclasses give each kind of id its own type, so a `ChunkId` cannot be
    passed where an `ItemId` is expected (mypy catches it).
    """

    __slots__ = ()

    def __new__(cls, value: str) -> Self:
        """Validate and wrap `value`.

        Raises:
            ValueError: `value` is not 32 hex digits.
        """
        if type(value) is str and _HEX32.fullmatch(value):  # the usual, canonical form
            return str.__new__(cls, value)
        text = str(value).lower()
        if not _HEX32.fullmatch(text):
            raise ValueError(f"not a {cls.__name__}: {value!r} (expected 32 hex digits)")
        return super().__new__(cls, text)

    @classmethod
    def new(cls) -> Self:
        """A fresh random id."""
        # token_hex is 32 lowercase hex digits by construction: no need to check it
        return str.__new__(cls, secrets.token_hex(16))

    @classmethod
    def from_bytes(cls, raw: bytes) -> Self:
        """The id whose 16-byte big-endian form is `raw`."""
        if len(raw) != 16:
            raise ValueError(f"{cls.__name__} needs 16 bytes, got {len(raw)}")
        return str.__new__(cls, raw.hex())  # 32 lowercase hex digits by construction

    def to_bytes(self) -> bytes:
        """The 16-byte form used on the wire."""
        return bytes.fromhex(self)

    @property
    def short(self) -> str:
        """The first 8 hex digits, for humans (like a short git hash)."""
        return self[:8]


class ItemId(Id):
    """Identifies one item of a table."""


class ChunkId(Id):
    """Identifies one chunk, the unit of replication and locking."""


class PeerId(Id):
    """Identifies one peer of the swarm."""


class CommitId(Id):
    """Identifies one commit."""


def ring_key(data: str | bytes) -> int:
    """The 160-bit Chord key of `data`: SHA-1 read as a big-endian integer."""
    raw = data.encode() if isinstance(data, str) else data
    return int.from_bytes(hashlib.sha1(raw).digest(), "big")
