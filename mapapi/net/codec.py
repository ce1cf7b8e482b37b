"""The wire codec: the one module that sees the envelope's generated protobuf
(`wire_pb2`); the core's values inside it go through the storage codec
(`mapapi.core.codec`), and the Chord index's values are opaque bytes to it.

Everything above it (transport, rpc, the Raft groups, commit and Chord code)
works with the frozen dataclasses defined here: `Envelope` and its bodies.
A body is registered once in `_BODIES` with the name of its `oneof body` field
in `proto/mapapi/v1/wire.proto` and two converters; adding a message means
adding a proto field, a dataclass and one `_register` call below.

Decoding never trusts its input: anything that does not parse, lacks a field the
protocol needs or carries an unknown body raises `ProtocolError` (DESIGN §11).
"""

from __future__ import annotations

import enum
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from typing import Any, Generic, TypeVar

from google.protobuf.message import DecodeError

from mapapi._pb.mapapi.v1 import wire_pb2
from mapapi.core import codec as storage
from mapapi.core import limits
from mapapi.core.change import Conflict
from mapapi.core.errors import ConflictError, LimitExceeded, MapError, ProtocolError
from mapapi.core.ids import PeerId
from mapapi.net import fields, messages, raft_codec
from mapapi.net.messages import RaftBatch

B = TypeVar("B")

_MAX_VARINT_BYTES = 10


class Kind(enum.IntEnum):
    """What an envelope is: values of `Envelope.Kind` in wire.proto."""

    REQUEST = wire_pb2.Envelope.KIND_REQUEST
    REPLY = wire_pb2.Envelope.KIND_REPLY
    NOTIFY = wire_pb2.Envelope.KIND_NOTIFY


@dataclass(frozen=True, slots=True)
class ErrorReply:
    """A failed request: the MapError code and its message (STYLE §4); a
    ConflictError's conflicts and the time they were seen travel with it."""

    code: int
    message: str
    conflicts: tuple[Conflict, ...] = ()
    seen_at: int = 0


@dataclass(frozen=True, slots=True)
class Ping:
    """Liveness probe; answered with a `Pong` echoing `payload`."""

    payload: bytes = b""


@dataclass(frozen=True, slots=True)
class Pong:
    """The reply to a `Ping`."""

    payload: bytes = b""


@dataclass(frozen=True, slots=True)
class Envelope:
    """One decoded message: header plus a registered body dataclass."""

    request_id: int
    sender: PeerId
    lamport: int
    kind: Kind
    body: object

    @property
    def body_name(self) -> str:
        """The body's `oneof` field name, e.g. "ping" (used as the message type in stats)."""
        return body_name(self.body)


@dataclass(frozen=True, slots=True)
class _BodyCodec(Generic[B]):
    field: str
    cls: type[B]
    fill: Callable[[B, Any], None]  # copies the dataclass into the (mutable) sub-message
    read: Callable[[Any], B]


_BODIES: dict[type, _BodyCodec[Any]] = {}
_BY_FIELD: dict[str, _BodyCodec[Any]] = {}
_ONEOF_FIELDS = {f.name for f in wire_pb2.Envelope.DESCRIPTOR.oneofs_by_name["body"].fields}


def _register(
    field: str, cls: type[B], fill: Callable[[B, Any], None], read: Callable[[Any], B]
) -> None:
    if field not in _ONEOF_FIELDS:
        raise ValueError(f"Envelope.body has no field {field!r}; add it to wire.proto")
    codec = _BodyCodec(field, cls, fill, read)
    _BODIES[cls] = codec
    _BY_FIELD[field] = codec


def _register_swarm_bodies() -> None:
    """Register every body of `mapapi.net.messages` with the generic converter."""
    for field, cls in messages.SWARM_BODIES.items():
        _register(field, cls, fields.fill, partial(fields.read, cls))


def _fill_error(b: ErrorReply, m: Any) -> None:
    m.code = b.code
    m.message = b.message
    m.conflicts.extend(storage.conflict_to_pb(c) for c in b.conflicts)
    m.seen_at = b.seen_at


def _read_error(m: Any) -> ErrorReply:
    limits.count("conflicts", len(m.conflicts))
    return ErrorReply(
        m.code,
        m.message,
        tuple(_read_conflict(c) for c in m.conflicts),
        limits.lamport("conflict time", m.seen_at),
    )


def _read_conflict(m: Any) -> Conflict:
    """A conflict of an ErrorReply, its fields checked against `mapapi.core.limits`."""
    for revision in (m.base, m.theirs):
        limits.size("table", revision.table)
        limits.size("data", revision.data)
        limits.lamport("revision update time", revision.update_time)
    limits.size("table", m.table)
    limits.size("data", m.ours.data)
    return storage.conflict_from_pb(m)


def _fill_payload(b: Ping | Pong, m: Any) -> None:
    m.SetInParent()  # an empty payload must still select the oneof field
    m.payload = b.payload


_register("error", ErrorReply, _fill_error, _read_error)
_register_swarm_bodies()
_register("raft_batch", RaftBatch, raft_codec.fill_batch, raft_codec.read_batch)  # the hot path
_register("ping", Ping, _fill_payload, lambda m: Ping(m.payload))
_register("pong", Pong, _fill_payload, lambda m: Pong(m.payload))


def body_types() -> tuple[type, ...]:
    """Every body dataclass the codec knows."""
    return tuple(_BODIES)


def body_name(body: object) -> str:
    """The `oneof` field name of a body instance or class.

    Raises:
        TypeError: it is not a registered body.
    """
    cls = body if isinstance(body, type) else type(body)
    codec = _BODIES.get(cls)
    if codec is None:
        raise TypeError(f"{cls.__name__} is not a registered envelope body")
    return codec.field


_KINDS = {k.value: k for k in Kind}
_SENDERS: dict[bytes, PeerId] = {}  # a swarm has few peers; skip re-validating their ids
_MAX_SENDERS = 4096


def _sender(raw: bytes) -> PeerId:
    peer = _SENDERS.get(raw)
    if peer is None:
        if len(raw) != 16:
            raise ProtocolError(f"envelope sender is {len(raw)} bytes, expected 16")
        if len(_SENDERS) >= _MAX_SENDERS:
            _SENDERS.clear()
        peer = _SENDERS[raw] = PeerId(raw.hex())
    return peer


def encode(env: Envelope) -> bytes:
    """Serialize an envelope.

    Raises:
        TypeError: the body is not a registered body type.
    """
    codec = _BODIES.get(type(env.body))
    if codec is None:
        raise TypeError(f"{type(env.body).__name__} is not a registered envelope body")
    m = wire_pb2.Envelope(
        request_id=env.request_id,
        sender=env.sender.to_bytes(),
        lamport=env.lamport,
        kind=int(env.kind),  # type: ignore[arg-type]
    )
    codec.fill(env.body, getattr(m, codec.field))
    return bytes(m.SerializeToString())


def decode(data: bytes) -> Envelope:
    """Parse and validate an envelope.

    Raises:
        ProtocolError: the bytes do not parse, a header field is missing or
            invalid (a Lamport time above `limits.MAX_LAMPORT`), the body is
            absent or unknown to this version, or a field of it exceeds its
            limit in `mapapi.core.limits` (checked before the body is built).
    """
    m = wire_pb2.Envelope()
    try:
        m.ParseFromString(data)
    except (DecodeError, ValueError, RuntimeError) as exc:
        raise ProtocolError(f"undecodable envelope ({len(data)} bytes): {exc}") from exc
    kind = _KINDS.get(m.kind)
    if kind is None:
        raise ProtocolError(f"envelope of unknown kind {m.kind}")
    try:
        limits.lamport("envelope Lamport time", m.lamport)
    except LimitExceeded as exc:
        raise ProtocolError(str(exc)) from None
    sender = _sender(m.sender)
    if kind is not Kind.NOTIFY and m.request_id == 0:
        raise ProtocolError(f"{kind.name.lower()} without a request id")
    field = m.WhichOneof("body")
    codec = _BY_FIELD.get(field) if field is not None else None
    if codec is None:
        raise ProtocolError("envelope with no body, or one this version does not know")
    try:
        body = codec.read(getattr(m, field))
    except (ValueError, TypeError) as exc:
        raise ProtocolError(f"invalid {field} body: {exc}") from exc
    return Envelope(m.request_id, sender, m.lamport, kind, body)


def peek_request_id(data: bytes) -> int | None:
    """The request id of a message that may be truncated or otherwise broken.

    `encode` writes field 1 (request_id) first, so it can be read from the
    prefix alone; this lets a peer answer a broken request with an ErrorReply.
    Returns None when the prefix does not start with a complete field 1.
    """
    if len(data) < 2 or data[0] != 0x08:  # tag of field 1, wire type varint
        return None
    value = 0
    for i, byte in enumerate(data[1 : 1 + _MAX_VARINT_BYTES]):
        value |= (byte & 0x7F) << (7 * i)
        if not byte & 0x80:
            return value if 0 < value < 1 << 64 else None
    return None


def _error_classes() -> dict[int, type[MapError]]:
    table: dict[int, type[MapError]] = {}
    todo: list[type[MapError]] = [MapError]
    while todo:  # breadth first: on a shared code, the more general class wins
        cls = todo.pop(0)
        table.setdefault(cls.code, cls)
        todo.extend(cls.__subclasses__())
    return table


_ERRORS: dict[int, type[MapError]] = {}


def error_class(code: int) -> type[MapError]:
    """The MapError subclass whose `code` is `code`; `ProtocolError` if none is.

    The table is built from `MapError.__subclasses__()` (STYLE §4) and rebuilt
    once on a miss, so error classes defined after the first lookup are found.
    """
    global _ERRORS
    if code not in _ERRORS:
        _ERRORS = _error_classes()
    return _ERRORS.get(code, ProtocolError)


def error_reply(exc: MapError) -> ErrorReply:
    """The reply that carries `exc` to the requester (a ConflictError's
    conflicts included)."""
    if isinstance(exc, ConflictError):
        return ErrorReply(exc.code, str(exc), tuple(exc.conflicts), exc.seen_at)
    return ErrorReply(exc.code, str(exc))


def error_from_reply(reply: ErrorReply) -> MapError:
    """The exception a received ErrorReply stands for (unknown codes: ProtocolError)."""
    cls = error_class(reply.code)
    if cls is ProtocolError and reply.code != ProtocolError.code:
        return ProtocolError(f"peer replied unknown error code {reply.code}: {reply.message}")
    if issubclass(cls, ConflictError):
        return cls.received(reply.message, list(reply.conflicts), reply.seen_at)
    if not cls.advice:
        try:
            return cls(reply.message)
        except TypeError:  # a class whose __init__ takes structured arguments
            pass
    # The message is whole, its advice included (an advised class would append
    # its own advice again, after the sender's).
    exc = cls.__new__(cls)
    Exception.__init__(exc, reply.message)
    return exc
