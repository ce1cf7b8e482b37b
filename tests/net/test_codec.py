"""The wire codec: round trips, hostile input, the error-code table."""

from __future__ import annotations

import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from mapapi.core import errors, limits
from mapapi.core.errors import ConflictError, LockTimeout, MapError, ProtocolError
from mapapi.core.ids import PeerId
from mapapi.net import codec, messages
from mapapi.net.codec import Envelope, ErrorReply, Kind, Ping, Pong

U64 = st.integers(0, 2**64 - 1)
LAMPORT = st.integers(0, limits.MAX_LAMPORT)  # above it an envelope is refused (test_limits)
bodies = st.one_of(
    st.builds(Ping, st.binary(max_size=64)),
    st.builds(Pong, st.binary(max_size=64)),
    st.builds(ErrorReply, st.integers(0, 2**32 - 1), st.text(max_size=40)),
)
envelopes = st.builds(
    Envelope,
    request_id=st.integers(1, 2**64 - 1),
    sender=st.binary(min_size=16, max_size=16).map(PeerId.from_bytes),
    lamport=LAMPORT,
    kind=st.sampled_from(Kind),
    body=bodies,
)


def _valid(**overrides: object) -> Envelope:
    fields: dict[str, object] = {
        "request_id": 7,
        "sender": PeerId("ab" * 16),
        "lamport": 42,
        "kind": Kind.REQUEST,
        "body": Ping(b"payload"),
    }
    fields.update(overrides)
    return Envelope(**fields)  # type: ignore[arg-type]


class TestRoundTrip:
    @given(envelopes)
    def test_decode_inverts_encode(self, env: Envelope) -> None:
        assert codec.decode(codec.encode(env)) == env

    def test_empty_payload_still_selects_the_body(self) -> None:
        env = _valid(body=Ping())
        assert codec.decode(codec.encode(env)).body == Ping()

    def test_notify_may_have_no_request_id(self) -> None:
        env = _valid(kind=Kind.NOTIFY, request_id=0)
        assert codec.decode(codec.encode(env)) == env

    def test_body_names_are_the_oneof_fields(self) -> None:
        names = {codec.body_name(t) for t in codec.body_types()}
        assert {"error", "ping", "pong", *messages.SWARM_BODIES} == names
        assert _valid().body_name == "ping"

    def test_unregistered_body_is_a_caller_mistake(self) -> None:
        with pytest.raises(TypeError, match="not a registered envelope body"):
            codec.encode(_valid(body="text"))


class TestHostileInput:
    @given(st.binary(max_size=200))
    @example(b"")
    @example(b"\x08")
    @example(b"\xff" * 20)
    def test_random_bytes_raise_protocol_error_or_decode_cleanly(self, data: bytes) -> None:
        try:
            env = codec.decode(data)
        except ProtocolError:
            return
        # the rare random string that is a valid envelope must survive a round trip
        assert codec.decode(codec.encode(env)) == env

    def test_every_truncation_raises_protocol_error(self) -> None:
        data = codec.encode(_valid())
        for cut in range(len(data)):
            with pytest.raises(ProtocolError):
                codec.decode(data[:cut])

    def test_request_without_id(self) -> None:
        with pytest.raises(ProtocolError, match="without a request id"):
            codec.decode(_raw(request_id=0))

    @pytest.mark.parametrize("kind", [0, 4, 1000])
    def test_unknown_kind(self, kind: int) -> None:
        with pytest.raises(ProtocolError, match="unknown kind"):
            codec.decode(_raw(kind=kind))

    def test_short_sender_is_rejected(self) -> None:
        with pytest.raises(ProtocolError, match="sender is 3 bytes"):
            codec.decode(_raw(sender=b"abc"))

    def test_unknown_body_from_a_newer_peer(self) -> None:
        data = _raw(body=b"")  # header only ...
        data += bytes([0x9A, 0x06, 0x00])  # ... plus field 99, empty, unknown here
        with pytest.raises(ProtocolError, match="no body"):
            codec.decode(data)
        assert codec.peek_request_id(data) == 7

    @given(envelopes, st.data())
    def test_request_id_survives_truncation(self, env: Envelope, data: st.DataObject) -> None:
        blob = codec.encode(env)
        header = 1 + len(_varint(env.request_id))
        cut = data.draw(st.integers(header, len(blob)))
        assert codec.peek_request_id(blob[:cut]) == env.request_id

    @pytest.mark.parametrize("data", [b"", b"\x08", b"\x08\x80", b"\x10\x01", b"\x08\x00"])
    def test_no_request_id_to_peek(self, data: bytes) -> None:
        assert codec.peek_request_id(data) is None


class _Structured(MapError):
    """A test error whose constructor takes structured arguments."""

    code = 9_901

    def __init__(self, a: int, b: int) -> None:
        super().__init__(f"{a} and {b}")


class TestErrorCodes:
    def test_codes_of_mapapi_errors_are_distinct(self) -> None:
        classes = [
            c for c in vars(errors).values() if isinstance(c, type) and issubclass(c, MapError)
        ]
        codes = [c.code for c in classes]
        assert len(codes) == len(set(codes)), sorted(codes)
        assert all(codec.error_class(c.code) is c for c in classes)

    def test_network_errors(self) -> None:
        assert errors.PeerUnavailable.retriable
        assert errors.RequestTimeout.retriable
        assert not ProtocolError.retriable
        assert issubclass(ProtocolError, errors.NetworkError)

    def test_reply_round_trip_keeps_class_and_message(self) -> None:
        exc = codec.error_from_reply(codec.error_reply(LockTimeout("lock on c1 not granted")))
        assert type(exc) is LockTimeout
        assert str(exc) == "lock on c1 not granted"

    def test_unknown_code_becomes_protocol_error(self) -> None:
        exc = codec.error_from_reply(ErrorReply(65_000, "from the future"))
        assert type(exc) is ProtocolError
        assert "65000" in str(exc)

    def test_structured_errors_still_arrive_as_their_class(self) -> None:
        exc = codec.error_from_reply(codec.error_reply(_Structured(1, 2)))
        assert type(exc) is _Structured
        assert str(exc) == "1 and 2"

    def test_conflict_error_code_maps_back(self) -> None:
        assert codec.error_class(ConflictError.code) is ConflictError


def _varint(n: int) -> bytes:
    out = bytearray()
    while True:
        byte, n = n & 0x7F, n >> 7
        out.append(byte | (0x80 if n else 0))
        if not n:
            return bytes(out)


def _raw(
    request_id: int = 7, sender: bytes = b"\xab" * 16, kind: int = 1, body: bytes | None = None
) -> bytes:
    """Hand-built envelope bytes, to express what `encode` refuses to write."""
    out = b""
    if request_id:
        out += b"\x08" + _varint(request_id)
    out += b"\x12" + _varint(len(sender)) + sender
    out += b"\x18" + _varint(42)
    if kind:
        out += b"\x20" + _varint(kind)
    ping = b"\x5a\x02\x0a\x00" if body is None else body  # field 11 (ping), payload b""
    return out + ping
