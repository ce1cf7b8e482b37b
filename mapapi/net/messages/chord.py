"""The Chord ring's messages (DESIGN §7); ring keys travel as 20 big-endian bytes.

Plain frozen dataclasses, each mapping field by field onto the message of the
same name in `proto/mapapi/v1/wire.proto` (see `mapapi.net.messages`).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class ChordPeer:
    """A node of the ring: its key (20 bytes) and its Rpc address."""

    key: bytes
    address: str


@dataclass(frozen=True, slots=True)
class ChordFindSuccessor:
    """One step of an iterative lookup of `key`, ignoring the nodes in `avoid`."""

    key: bytes
    avoid: tuple[bytes, ...] = ()


@dataclass(frozen=True, slots=True)
class ChordHop:
    """`node` is the successor of the key (`final`) or the next node to ask."""

    node: ChordPeer
    final: bool


@dataclass(frozen=True, slots=True)
class ChordGetNeighbours:
    """Ask a node for its predecessor and successor list (also a liveness probe)."""


@dataclass(frozen=True, slots=True)
class ChordNeighbours:
    """A node's predecessor (zero or one) and successor list."""

    predecessor: tuple[ChordPeer, ...]
    successors: tuple[ChordPeer, ...]


@dataclass(frozen=True, slots=True)
class ChordNotify:
    """`node` thinks it might be the receiver's predecessor (Chord Fig. 7)."""

    node: ChordPeer


@dataclass(frozen=True, slots=True)
class ChordLeave:
    """`node` leaves gracefully; its predecessor (zero or one) and successors."""

    node: ChordPeer
    predecessor: tuple[ChordPeer, ...]
    successors: tuple[ChordPeer, ...]


@dataclass(frozen=True, slots=True)
class ChordAdd:
    """Add `member` to the set under `key` for `ttl` seconds (atomic at the owner)."""

    key: bytes
    member: bytes
    ttl: float
    replica: bool = False


@dataclass(frozen=True, slots=True)
class ChordRemove:
    """Remove `member` from the set under `key`."""

    key: bytes
    member: bytes
    replica: bool = False


@dataclass(frozen=True, slots=True)
class ChordGet:
    """The live members under `key`; with `filter`, those the node's filter of
    that name keeps for `argument`."""

    key: bytes
    filter: str = ""
    argument: bytes = b""


@dataclass(frozen=True, slots=True)
class ChordValues:
    """The answer to `ChordGet`."""

    members: tuple[bytes, ...]


@dataclass(frozen=True, slots=True)
class ChordEntry:
    """One stored member and the seconds it has left."""

    key: bytes
    member: bytes
    ttl: float


@dataclass(frozen=True, slots=True)
class ChordStore:
    """Entries to store; with `replicate` the receiver owns them and copies them on."""

    entries: tuple[ChordEntry, ...]
    replicate: bool = False


BODIES: dict[str, type] = {
    "chord_find_successor": ChordFindSuccessor,
    "chord_hop": ChordHop,
    "chord_get_neighbours": ChordGetNeighbours,
    "chord_neighbours": ChordNeighbours,
    "chord_notify": ChordNotify,
    "chord_leave": ChordLeave,
    "chord_add": ChordAdd,
    "chord_remove": ChordRemove,
    "chord_get": ChordGet,
    "chord_values": ChordValues,
    "chord_store": ChordStore,
}
"""Envelope body field -> class, for the messages of this area."""
