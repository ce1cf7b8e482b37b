"""What the transport receives: checked, counted, reassembled, then handed to the sink.

`Receiver` takes the frames the transport's readers drain and decides, for each,
whether it reaches the RPC layer (DESIGN §11): malformed, oversized, unexpected
and forged messages are dropped and counted under a reason, and a request among
them is answered with an ErrorReply when its request id can be recovered. It
merges each accepted Lamport time into the clock (DESIGN §4), reassembles
messages sent as parts (`mapapi.net.parts`) within the peer's budget, and on a
secure peer refuses a message whose `sender` is not the id its connection's key
speaks as (docs/design.md "Secure swarm").
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

from mapapi.core import limits
from mapapi.core.clock import LamportClock
from mapapi.core.errors import AccessRefused, LimitExceeded, ProtocolError
from mapapi.core.ids import PeerId
from mapapi.net import codec, parts
from mapapi.net.codec import Envelope, ErrorReply, Kind
from mapapi.net.security import Security, key_text
from mapapi.net.stats import Stats

log = logging.getLogger(__name__)

_MAX_FORGERS_LOGGED = 1_024  # (key, claimed id) pairs warned about once each


@dataclass(frozen=True, slots=True)
class Route:
    """Where the reply to an inbound request goes: a ROUTER routing id."""

    routing_id: bytes
    peer: str  # the stats key of the remote: its PeerId, or "?<routing id>" if unknown


@dataclass(frozen=True, slots=True)
class Inbound:
    """A decoded message handed to the sink.

    Requests and notifications carry the `route` to reply on; replies carry the
    `address` of the link they came back on.
    """

    envelope: Envelope
    route: Route | None
    address: str | None
    size: int


class Sink(Protocol):
    """Receives what the transport decodes; must not block (it runs in a reader)."""

    def on_message(self, msg: Inbound) -> None:
        """A decoded, clock-merged message."""

    def on_broken_reply(self, address: str, request_id: int, error: ProtocolError) -> None:
        """A reply for `request_id` arrived from `address` but could not be decoded."""

    def on_link_refused(self, address: str, error: AccessRefused) -> None:
        """The link to `address` can never work (see `mapapi.net.curve.LinkWatch`)."""


Reply = Callable[[Route, int, object], None]


class Receiver:
    """Turns drained frames into `Inbound` messages for the sink (see the module doc).

    Args:
        peer_id: this peer (for logs).
        clock: the Lamport clock to merge received times into.
        stats: where receptions and drops are counted.
        max_message_size: larger messages are dropped ("oversized").
        security: a secure peer's keys and trust list (None: senders are not checked).
        reply: answers a request on the ROUTER (the transport's `reply`).
    """

    def __init__(
        self,
        peer_id: PeerId,
        clock: LamportClock,
        stats: Stats,
        max_message_size: int,
        security: Security | None,
        reply: Reply,
    ) -> None:
        self.peer_id = peer_id
        self.clock = clock
        self.stats = stats
        self.max_message_size = max_message_size
        self.security = security
        self.sink: Sink | None = None
        self.closed = False
        self.parts = parts.Reassembly(
            max_message_size, limits.MAX_BUFFERED_BYTES, limits.STALLED_TRANSFER_S
        )
        self._reply = reply
        self._forgers: set[tuple[bytes, str]] = set()

    # -- requests and notifications, on the ROUTER ----------------------------------
    def on_router(self, frames: list[bytes], key: bytes | None = None) -> None:
        """Frames from the ROUTER: `[routing id, message]` or `[routing id, header,
        chunk]` (a part); `key` is the CURVE key the connection authenticated with."""
        route = Route(frames[0], "?" + frames[0].hex())
        if len(frames) == 3 and parts.is_part_header(frames[1]):
            now = asyncio.get_running_loop().time()
            done = self.parts.add(frames[0], frames[1], frames[2], now)
            if isinstance(done, parts.Refused):
                self._reject(route, done.first, done.reason, len(frames[2]), done.why)
            elif done is not None:
                self._on_request(route, done, key)
            return
        data = frames[1] if len(frames) > 1 else b""
        size = sum(len(f) for f in frames[1:])
        if len(frames) != 2 or size > self.max_message_size:
            reason = "oversized" if size > self.max_message_size else "malformed"
            self._reject(route, data, reason, size, f"{reason} message ({size} bytes)")
            return
        self._on_request(route, data, key)

    def _on_request(self, route: Route, data: bytes, key: bytes | None) -> None:
        size = len(data)
        try:
            env = codec.decode(data)
        except ProtocolError as exc:
            self._reject(route, data, "malformed", size, str(exc))
            return
        peer = str(env.sender)
        if env.kind is Kind.REPLY:
            self.stats.record_dropped(peer, "unexpected", size)
            return
        if self.security is not None and not self._sender_holds(key, env, route, size):
            return
        try:
            self._merge(env.lamport)
        except ProtocolError as exc:
            self.stats.record_dropped(peer, "malformed", size)
            if env.kind is Kind.REQUEST:  # a notification is never answered
                self._reply(route, env.request_id, ErrorReply(exc.code, str(exc)))
            return
        self.stats.record_received(peer, env.body_name, size)
        if self.sink is not None:
            self.sink.on_message(Inbound(env, Route(route.routing_id, peer), None, size))

    def _sender_holds(self, key: bytes | None, env: Envelope, route: Route, size: int) -> bool:
        """Whether `env.sender` is the id the connection's key speaks as; if not,
        the message is dropped, counted ("forged"), logged and, if a request, refused."""
        assert self.security is not None
        if key is not None and self.security.speaks_as(key, env.sender):
            return True
        expected = self.security.id_of(key) if key is not None else None
        self.stats.record_dropped(route.peer, "forged", size)
        shown = key_text(key) if key is not None else "(none)"
        if (
            len(self._forgers) < _MAX_FORGERS_LOGGED
            and (key or b"", env.sender) not in self._forgers
        ):
            self._forgers.add((key or b"", env.sender))  # a forger may retry: say it once
            log.warning(
                "refused a %s from key %s claiming to be peer %s: that key speaks as %s",
                env.body_name,
                shown,
                env.sender,
                expected,
            )
        if env.kind is Kind.REQUEST:
            why = f"the sender {env.sender} is not the peer of this connection's key ({shown})"
            self._reply(route, env.request_id, ErrorReply(AccessRefused.code, why))
        return False

    def _reject(self, route: Route, data: bytes, reason: str, size: int, why: str) -> None:
        self.stats.record_dropped(route.peer, reason, size)
        request_id = codec.peek_request_id(data)
        log.debug("dropped %s message from %s: %s", reason, route.peer, why)
        if request_id is not None and not self.closed:
            self._reply(route, request_id, ErrorReply(ProtocolError.code, why))

    # -- replies, on a DEALER ---------------------------------------------------------------
    def on_dealer(self, address: str, frames: list[bytes], key: bytes | None) -> None:
        """Frames from the DEALER linked to `address`: `[message]` or `[header,
        chunk]`; `key` is the remote's key, which the link's handshake proved."""
        if len(frames) == 2 and parts.is_part_header(frames[0]):
            now = asyncio.get_running_loop().time()
            done = self.parts.add(address, frames[0], frames[1], now)
            if isinstance(done, parts.Refused):
                self._broken(address, done.first, done.reason, len(frames[1]), done.why)
            elif done is not None:
                self._on_reply(address, done, key)
            return
        size = sum(len(f) for f in frames)
        data = frames[0] if frames else b""
        if len(frames) != 1 or size > self.max_message_size:
            reason = "oversized" if size > self.max_message_size else "malformed"
            self._broken(
                address, data, reason, size, f"{reason} reply from {address} ({size} bytes)"
            )
            return
        self._on_reply(address, data, key)

    def _on_reply(self, address: str, data: bytes, key: bytes | None) -> None:
        size = len(data)
        try:
            env = codec.decode(data)
        except ProtocolError as exc:
            self._broken(address, data, "malformed", size, str(exc))
            return
        if env.kind is not Kind.REPLY:
            self.stats.record_dropped(address, "unexpected", size)
            return
        if (
            key is not None
            and self.security is not None
            and not self.security.speaks_as(key, env.sender)
        ):
            expected = self.security.id_of(key)
            # The link's CURVE handshake proved the remote holds the key its
            # address names; a reply naming another peer is forged.
            why = f"a reply from {address} claims to come from {env.sender}, not {expected}"
            log.warning("refused %s", why)
            self._broken(address, data, "forged", size, why)
            return
        try:
            self._merge(env.lamport)
        except ProtocolError as exc:
            self._broken(address, data, "malformed", size, str(exc))
            return
        self.stats.record_received(address, env.body_name, size)
        if self.sink is not None:
            self.sink.on_message(Inbound(env, None, address, size))

    def _broken(self, address: str, data: bytes, reason: str, size: int, why: str) -> None:
        self.stats.record_dropped(address, reason, size)
        request_id = codec.peek_request_id(data)
        if request_id is not None and self.sink is not None:
            self.sink.on_broken_reply(address, request_id, ProtocolError(why))

    def _merge(self, lamport: int) -> None:
        """Fold a received Lamport time into the clock (DESIGN §4).

        Raises:
            ProtocolError: the time is more than `limits.MAX_CLOCK_JUMP` ahead.
        """
        try:
            limits.clock_jump(self.clock.now(), lamport)
        except LimitExceeded as exc:
            raise ProtocolError(str(exc)) from None
        self.clock.merge(lamport)
