"""A node of the Chord ring, and how it and ring keys travel on the wire
(keys as 20 big-endian bytes, nodes as `ChordPeer`)."""

from __future__ import annotations

from typing import NamedTuple

from mapapi.core.errors import ProtocolError
from mapapi.lookup.dht import ring
from mapapi.net.messages import ChordPeer

_KEY_BYTES = ring.RING_BITS // 8


class Node(NamedTuple):
    """A node of the ring: its key and its Rpc address."""

    key: int
    address: str


def key_bytes(key: int) -> bytes:
    """A ring key as it travels: 20 big-endian bytes."""
    return key.to_bytes(_KEY_BYTES, "big")


def key_from(raw: bytes) -> int:
    """The ring key of 20 wire bytes.

    Raises:
        ProtocolError: not 20 bytes.
    """
    if len(raw) != _KEY_BYTES:
        raise ProtocolError(f"a ring key is {_KEY_BYTES} bytes, got {len(raw)}")
    return int.from_bytes(raw, "big")


def wire(node: Node) -> ChordPeer:
    return ChordPeer(key_bytes(node.key), node.address)


def node_of(peer: ChordPeer) -> Node:
    return Node(key_from(peer.key), peer.address)
