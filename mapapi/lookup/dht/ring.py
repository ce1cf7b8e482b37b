"""Chord id arithmetic on the 2^160 ring (DESIGN §7), pure: no sockets, no asyncio.

Keys and node ids are ints in ``[0, 2**160)``: SHA-1 digests read big-endian
(`mapapi.core.ids.ring_key`). The C++ original hashed into 16 bits and never filled
its fingers, so lookups walked the ring in O(n) hops (research notes §3.4); here
`finger_start` / `closest_preceding` / `next_hop` are the routing rules of the
Chord paper (Stoica et al., SIGCOMM 2001, Fig. 5), and `SortedRing` is the
global view the tests compare a running ring against.

Intervals follow the paper: ``(a, b)`` and ``(a, b]`` run clockwise from `a`
and wrap past zero. When ``a == b`` the interval is the whole ring, less `a`
itself when it is open; so in a one-node ring the node is responsible for
every key and its own successor.
"""

from __future__ import annotations

from bisect import bisect_left, bisect_right
from collections.abc import Iterable, Iterator, Sequence
from typing import NamedTuple

from mapapi.core.ids import ChunkId, PeerId, ring_key

RING_BITS = 160
"""Bits of a ring key (SHA-1)."""

RING_SIZE = 1 << RING_BITS
"""Number of keys on the ring; all arithmetic is modulo this."""


def _check_key(value: int, what: str = "key") -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < RING_SIZE:
        raise ValueError(f"a ring {what} is an int in [0, 2**{RING_BITS}), got {value!r}")
    return value


def peer_key(peer_id: PeerId) -> int:
    """A peer's position on the ring: SHA-1 of the 16 bytes of its id."""
    return ring_key(peer_id.to_bytes())


def chunk_key(chunk_id: ChunkId) -> int:
    """The ring key under which a chunk's holders are stored (lookup by reference):
    SHA-1 of the 16 bytes of its id."""
    return ring_key(chunk_id.to_bytes())


def distance(a: int, b: int) -> int:
    """The clockwise distance from `a` to `b`: ``(b - a) mod 2**160``."""
    return (_check_key(b) - _check_key(a)) % RING_SIZE


def in_interval(x: int, a: int, b: int, *, inclusive_right: bool) -> bool:
    """Whether `x` lies in ``(a, b)``, or ``(a, b]`` with `inclusive_right`, clockwise.

    The interval wraps past zero when ``b <= a``. With ``a == b``, ``(a, a]`` is
    the whole ring and ``(a, a)`` the whole ring except `a` (Chord's convention,
    which makes a single node its own successor).

    Raises:
        ValueError: an argument is not a ring key.
    """
    dx = distance(a, x)
    db = distance(a, b)
    if db == 0:
        db = RING_SIZE
    return 0 < dx < db or (inclusive_right and dx == db % RING_SIZE)


def finger_start(n: int, i: int) -> int:
    """The start of node `n`'s finger `i`: ``(n + 2**i) mod 2**160``.

    Finger `i` is the successor of this key; finger 0 is the immediate successor.

    Raises:
        ValueError: `n` is not a ring key, or `i` is not in ``[0, 160)``.
    """
    _check_key(n, "node")
    if isinstance(i, bool) or not isinstance(i, int) or not 0 <= i < RING_BITS:
        raise ValueError(f"finger index must be in [0, {RING_BITS}), got {i!r}")
    return (n + (1 << i)) % RING_SIZE


def closest_preceding(
    n: int, key: int, fingers: Iterable[int | None], successors: Iterable[int] = ()
) -> int:
    """Among the nodes `n` knows, the one closest before `key` (Chord paper Fig. 5).

    Candidates are the finger table (``None`` for a slot not yet filled) and the
    successor list; the result is the candidate in the open interval
    ``(n, key)`` nearest to `key`, or `n` itself when none lies there. Order and
    duplicates of the inputs do not matter.

    Raises:
        ValueError: an argument is not a ring key.
    """
    best, best_distance = n, 0
    span = distance(n, key) or RING_SIZE  # (n, n) is the ring less n
    for candidate in (*fingers, *successors):
        if candidate is None:
            continue
        d = distance(n, candidate)
        if best_distance < d < span:
            best, best_distance = candidate, d
    return best


class Hop(NamedTuple):
    """One routing decision of `next_hop`.

    Attributes:
        node: the answer (when `final`) or the node to forward the lookup to.
        final: True when `node` is the successor of the key.
    """

    node: int
    final: bool


def next_hop(n: int, key: int, successors: Sequence[int], fingers: Iterable[int | None]) -> Hop:
    """What node `n` does with a lookup for `key`: answer it, or forward it.

    `find_successor` of the Chord paper: if `key` is in ``(n, successor]`` the
    successor is the answer; otherwise forward to `closest_preceding`. Because
    the successor is itself a candidate, the forward always moves clockwise
    past `n` and at least halves the distance to `key` when fingers are right.

    Args:
        n: this node's key.
        key: the key looked up.
        successors: this node's successor list; ``successors[0]`` is its successor
            (``n`` itself in a one-node ring).
        fingers: this node's finger table, ``None`` where not yet known.

    Raises:
        ValueError: `successors` is empty, or an argument is not a ring key.
    """
    if not successors:
        raise ValueError("a node always knows a successor (itself when alone)")
    successor = successors[0]
    if in_interval(key, n, successor, inclusive_right=True):
        return Hop(successor, final=True)
    return Hop(closest_preceding(n, key, fingers, successors), final=False)


def responsible(key: int, node: int, predecessor: int) -> bool:
    """Whether `node`, whose predecessor is `predecessor`, stores `key`:
    ``key in (predecessor, node]``. A node that is its own predecessor is alone
    and stores every key.

    Raises:
        ValueError: an argument is not a ring key.
    """
    return in_interval(key, predecessor, node, inclusive_right=True)


class SortedRing:
    """The global, sorted view of a set of node keys: the oracle that a running
    Chord ring must agree with (STYLE §7), also handy for simulations.

    Args:
        nodes: node keys; duplicates are merged.

    Raises:
        ValueError: `nodes` is empty or holds a value that is not a ring key.
    """

    def __init__(self, nodes: Iterable[int]) -> None:
        self._nodes: tuple[int, ...] = tuple(sorted({_check_key(n, "node") for n in nodes}))
        if not self._nodes:
            raise ValueError("a ring needs at least one node")

    @property
    def nodes(self) -> tuple[int, ...]:
        """The node keys, ascending."""
        return self._nodes

    def __len__(self) -> int:
        return len(self._nodes)

    def __iter__(self) -> Iterator[int]:
        return iter(self._nodes)

    def __contains__(self, key: object) -> bool:
        i = bisect_left(self._nodes, key) if isinstance(key, int) else len(self._nodes)
        return i < len(self._nodes) and self._nodes[i] == key

    def __repr__(self) -> str:
        return f"SortedRing({len(self._nodes)} nodes)"

    def successor(self, key: int) -> int:
        """The first node at or clockwise after `key`: the node storing `key`."""
        i = bisect_left(self._nodes, _check_key(key))
        return self._nodes[i % len(self._nodes)]

    def predecessor(self, key: int) -> int:
        """The last node strictly before `key`, clockwise; so `key` is in
        ``(predecessor(key), successor(key)]``. In a one-node ring, that node."""
        i = bisect_left(self._nodes, _check_key(key))
        return self._nodes[i - 1]  # i == 0 wraps to the last node

    def successors(self, key: int, k: int) -> list[int]:
        """The first `k` distinct nodes from `successor(key)` on (fewer when the
        ring is smaller): where a key and its replicas live.

        Raises:
            ValueError: `k` is negative.
        """
        if k < 0:
            raise ValueError(f"k must be >= 0, got {k}")
        i = bisect_left(self._nodes, _check_key(key))
        size = len(self._nodes)
        return [self._nodes[(i + j) % size] for j in range(min(k, size))]

    def successor_list(self, node: int, k: int) -> list[int]:
        """The correct successor list of `node`: up to `k` other nodes clockwise
        after it, or ``[node]`` when it is alone.

        Raises:
            ValueError: `node` is not on the ring, or `k` < 1.
        """
        if node not in self:
            raise ValueError(f"{node:#x} is not a node of this ring")
        if k < 1:
            raise ValueError(f"a successor list holds at least 1 node, got k={k}")
        if len(self._nodes) == 1:
            return [node]
        i = bisect_right(self._nodes, node)
        size = len(self._nodes)
        return [self._nodes[(i + j) % size] for j in range(min(k, size - 1))]

    def finger_table(self, node: int) -> list[int]:
        """The correct finger table of `node`: entry `i` is
        ``successor(finger_start(node, i))``, for `i` in ``[0, 160)``."""
        return [self.successor(finger_start(node, i)) for i in range(RING_BITS)]
