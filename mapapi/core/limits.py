"""Every size and count limit a peer enforces on input, in one place (DESIGN §11).

A peer refuses what exceeds a limit before it allocates for it: a message over
`MAX_MESSAGE_BYTES` is dropped by the transport; a message over `FRAME_BYTES`
travels as parts of that size, and zmq itself cuts a connection that sends one
frame over twice `FRAME_BYTES` (`zmq.MAXMSGSIZE`, checked on the frame's header,
before it allocates); the parts being reassembled hold at most
`MAX_BUFFERED_BYTES` in all (`mapapi.net.parts`); a repeated field, a string or a
bytes field over its limit fails the decoding of its message, before one
dataclass of it is built; numbers out of range (a Lamport time near 2**64, a
time-to-live of 10**12 s, NaN) are refused where they are read. Each refusal
raises `LimitExceeded` (or the codec's `ProtocolError`), whose message names
the limit, so the sender learns which one it hit. docs/guarantees.md lists
them ("Hostile input").

The values are generous for a robot swarm's real traffic (a chunk's whole
history travels in one snapshot; swarms have tens of peers) and small enough that one
message cannot make a peer allocate much more than its own size.
"""

from __future__ import annotations

import math
import re

from mapapi.core.errors import LimitExceeded

MAX_MESSAGE_BYTES = 64 * 1024 * 1024
"""One message on the swarm's port; the transport drops larger ones."""

FRAME_BYTES = 1024 * 1024
"""The largest zmq frame a peer sends: a larger message goes as parts of this
size. A small frame keeps what libzmq buffers per connection small: it holds a
frame whole before handing it over, up to `RECEIVE_QUEUE` of them."""

RECEIVE_QUEUE = 16
"""Frames libzmq queues per inbound connection (`zmq.RCVHWM`) before it stops
reading that connection's socket (TCP then slows the sender, nothing is lost)."""

MAX_BUFFERED_BYTES = 96 * 1024 * 1024
"""Bytes of partly received messages a peer holds in all; a transfer that would
go beyond is refused (one message of `MAX_MESSAGE_BYTES` always fits)."""

STALLED_TRANSFER_S = 30.0
"""A partly received message with no new part for this long gives its share of
`MAX_BUFFERED_BYTES` to a new transfer that needs it."""

MAX_LAMPORT = 1 << 62
"""The largest Lamport time accepted from the wire, on an envelope, a revision or
a commit record (a clock pushed to 2**64 could no longer stamp a message, and
SQLite stores signed 64-bit integers)."""

MAX_CLOCK_JUMP = 1 << 40
"""How far ahead of the receiver's clock a message's Lamport time may be. A
hostile peer cannot push a clock to `MAX_LAMPORT` (where the swarm would refuse
its messages) with one message; a real peer is never 10**12 events ahead."""

MAX_PAYLOAD_BYTES = 16 * 1024 * 1024
"""One item's serialized payload (one revision's data)."""

MAX_TTL = 24 * 3600.0
"""The longest time-to-live (seconds) of a value stored in the Chord ring."""

MAX_NODE_STORAGE_BYTES = 256 * 1024 * 1024
"""What one Chord node stores for others, in member bytes (soft state)."""

MAX_STATS_KEYS = 100_000
"""(peer, message type) pairs a transport counts traffic under; beyond, new
peers share one key (`mapapi.net.stats.OTHERS`)."""

MAX_LINKS = 1_024
"""Outgoing links (one zmq socket each) a peer keeps open; beyond, the oldest
is closed (a later message reopens it)."""

MAX_COUNT: dict[str, int] = {
    "revisions": 200_000,  # per TriggerPush / RaftProposed
    "holders": 10_000,  # peers per message: a swarm is far smaller
    "members": 10_000,
    "predecessor": 1,
    "successors": 64,  # a successor list (Chord keeps a handful)
    "avoid": 1_024,  # ring keys a lookup routes around
    "entries": 1_000_000,  # Chord values handed over at once
    "chunks": 1_000_000,  # chunk summaries, or the chunks of one commit record
    "tables": 10_000,
    "where": 64,  # field filters of one subscription, evaluated on every commit
}
"""Elements of a repeated field, by field name; see `MAX_LIST` for the others."""

MAX_LIST = 1_000_000
"""Elements of any repeated field not in `MAX_COUNT`."""

MAX_TEXT: dict[str, int] = {
    "address": 1_024,  # a zmq endpoint
    "name": 1_024,  # a peer or table name
    "table": 1_024,
    "type_name": 1_024,
    "index": 4_096,  # a spatial index fingerprint
    "filter": 256,
    "op": 256,
    "message": 1024 * 1024,  # a commit message or an error reply
}
"""Characters of a string field, by field name (unlisted: only the frame limit,
e.g. the JSON of the local control endpoint)."""

MAX_BYTES: dict[str, int] = {
    "member": 64 * 1024,  # one Chord value: a holder, a spatial entry, a subscription
    "argument": 64 * 1024,  # a Chord filter's argument
    "subscription": 16,
    "data": MAX_PAYLOAD_BYTES,
}
"""Bytes of a bytes field, by field name (ids and ring keys have exact lengths)."""


PEER_ADDRESS = re.compile(
    r"(tcp://(\[[0-9a-fA-F:.]+\]|[^\s:/\[\]#]+):\d+|ipc://[^\s#]+)(#curve=[0-9a-fA-F]{64})?"
)
"""What a peer address looks like: tcp://HOST:PORT or ipc://PATH, then a secure
peer's public key (`mapapi.net.security.ADDRESS_KEY`: #curve=64 hex digits)."""


def address(value: str) -> str:
    """`value` if it is empty (no address known) or looks like a peer address.

    Raises:
        LimitExceeded: anything else (zmq could not connect to it).
    """
    size("address", value)
    if value and not PEER_ADDRESS.fullmatch(value):
        raise LimitExceeded(f"{value[:80]!r} is not a peer address (tcp://HOST:PORT or ipc://PATH)")
    return value


def count(field: str, n: int) -> None:
    """Refuse a repeated field `field` of `n` elements above its limit.

    Raises:
        LimitExceeded: naming the field and the limit.
    """
    limit = MAX_COUNT.get(field)
    name = f"MAX_COUNT[{field!r}]" if limit is not None else "MAX_LIST"
    limit = MAX_LIST if limit is None else limit
    if n > limit:
        raise LimitExceeded(f"{field}: {n} elements exceed the limit of {limit} ({name})")


def size(field: str, value: str | bytes) -> None:
    """Refuse a string or bytes field `field` longer than its limit (if it has one).

    Raises:
        LimitExceeded: naming the field and the limit.
    """
    text = isinstance(value, str)
    limit = (MAX_TEXT if text else MAX_BYTES).get(field)
    if limit is not None and len(value) > limit:
        unit, table = ("characters", "MAX_TEXT") if text else ("bytes", "MAX_BYTES")
        raise LimitExceeded(
            f"{field}: {len(value)} {unit} exceed the limit of {limit} ({table}[{field!r}])"
        )


def field(name: str, value: str | bytes) -> None:
    """Refuse a string or bytes field `name` over its limit, or an "address" field
    that is no peer address (both checked on every message read from the wire).

    Raises:
        LimitExceeded: naming the field and the limit.
    """
    if name == "address":
        address(value)  # type: ignore[arg-type]
    else:
        size(name, value)


def lamport(what: str, value: int) -> int:
    """`value` if it is a Lamport time a peer accepts.

    Raises:
        LimitExceeded: above `MAX_LAMPORT`.
    """
    if value > MAX_LAMPORT:
        raise LimitExceeded(f"{what} {value} exceeds the limit of 2**62 (MAX_LAMPORT)")
    return value


def clock_jump(now: int, remote: int) -> None:
    """Refuse a received Lamport time more than `MAX_CLOCK_JUMP` ahead of `now`.

    Raises:
        LimitExceeded: naming the limit.
    """
    if remote - now > MAX_CLOCK_JUMP:
        raise LimitExceeded(
            f"Lamport time {remote} is {remote - now} ahead of this peer's clock, more "
            "than 2**40 (MAX_CLOCK_JUMP)"
        )


def ttl(value: float) -> float:
    """`value` if it is a time-to-live a Chord node accepts: finite, in (0, MAX_TTL].

    Raises:
        LimitExceeded: NaN, infinite, not positive or above `MAX_TTL`.
    """
    if not (math.isfinite(value) and 0 < value <= MAX_TTL):
        raise LimitExceeded(f"time-to-live {value!r} s is outside (0, {MAX_TTL:g}] (MAX_TTL)")
    return value


def payload(n: int) -> None:
    """Refuse an item payload of `n` bytes above `MAX_PAYLOAD_BYTES`.

    Raises:
        LimitExceeded: naming the limit.
    """
    if n > MAX_PAYLOAD_BYTES:
        raise LimitExceeded(
            f"an item payload of {n} bytes exceeds the limit of {MAX_PAYLOAD_BYTES} "
            "(MAX_PAYLOAD_BYTES); split the item, or store the data elsewhere and a reference"
        )


def table_name(name: str) -> str:
    """`name` if a table of that name can travel: every message that carries a
    chunk (its revisions, its summary, a commit) names the table in a field of
    at most `MAX_TEXT["table"]` characters, so a longer name would be accepted
    locally and refused by every peer asked to replicate it.

    Raises:
        LimitExceeded: naming the limit.
    """
    limit = MAX_TEXT["table"]
    if len(name) > limit:
        raise LimitExceeded(
            f"a table name of {len(name)} characters exceeds the limit of {limit} "
            "(MAX_TEXT['table']): other peers could never replicate its chunks; "
            "choose a shorter name"
        )
    return name
