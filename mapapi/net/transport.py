"""Message transport over ZeroMQ: one ROUTER in, one DEALER per remote peer out.

Requests and notifications leave through the DEALER connected to the remote's
address and arrive on the remote's ROUTER; a reply goes back through that
ROUTER to the requesting DEALER. Each socket has one reader task that drains it
in batches (one awaited receive, then non-blocking receives until empty), decodes
and hands messages to a `Sink` (the RPC layer) without awaiting anything.

This module stamps the Lamport clock: `tick()` on every send; what arrives goes
through `mapapi.net.inbound.Receiver`, which merges it (DESIGN §4), counts it,
drops malformed, oversized and forged input, answering it with an ErrorReply
when the request id can be recovered (DESIGN §11). A message over
`limits.FRAME_BYTES` leaves as parts (`mapapi.net.parts`); every socket caps a
frame at twice that and queues few per connection, so memory stays bounded
whatever strangers send (issue 18 §5).

With a `Security` the sockets speak CurveZMQ (`mapapi.net.curve`, DESIGN §10):
the ROUTER admits trusted keys only, the address carries the public key
(`tcp://HOST:PORT#curve=KEY`), and each DEALER checks the key of the peer it
reaches. A secure transport sends as the id its key speaks as
(`Security.peer_id`) and refuses a message whose sender is another: the ROUTER
reads the key of each message's connection from the ZAP User-Id that
`curve.ZapHandler` gives it. Every new DEALER (`mapapi.net.links`), secure or not, has a handshake
monitor until its first handshake completes, so a link that can never work (a
refused key, a secure peer and an open one) fails its requests with
`AccessRefused` at once instead of timing out; it costs a few events per new
link, nothing per message, and no descriptors once the link works.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable, Coroutine
from typing import Any, Protocol, cast

import zmq
import zmq.asyncio

from mapapi.core import limits
from mapapi.core.clock import LamportClock
from mapapi.core.errors import AccessRefused, NetworkError, PeerUnavailable, ProtocolError
from mapapi.core.ids import PeerId
from mapapi.net import codec, curve, parts
from mapapi.net.codec import Envelope, ErrorReply, Kind
from mapapi.net.inbound import Inbound, Receiver, Route, Sink
from mapapi.net.links import Link
from mapapi.net.outbound import Outbox
from mapapi.net.security import Security, keyed_address, split_address
from mapapi.net.shaping import Shaper
from mapapi.net.stats import Stats

log = logging.getLogger(__name__)

DEFAULT_MAX_MESSAGE_SIZE = limits.MAX_MESSAGE_BYTES
"""Larger messages are dropped and counted (and refused on send)."""

_BATCH = 256  # messages drained per wake-up before other tasks get a turn
# plain ints: pyzmq's IntFlag arithmetic costs a microsecond per message
_EVENTS, _POLLIN, _NOBLOCK = int(zmq.EVENTS), int(zmq.POLLIN), int(zmq.NOBLOCK)
_HARD_LIMIT_FACTOR = 2  # libzmq disconnects senders of a frame beyond this multiple
_USER_ID = "User-Id"  # the ZAP user id of a message's connection: its key, in hex

__all__ = ["DEFAULT_MAX_MESSAGE_SIZE", "Inbound", "Route", "Sink", "Transport", "ZmqTransport"]


class Transport(Protocol):
    """The seam between the RPC layer and the sockets (STYLE §1)."""

    peer_id: PeerId
    clock: LamportClock
    stats: Stats

    @property
    def address(self) -> str:
        """The endpoint remote peers connect to."""

    def set_sink(self, sink: Sink) -> None:
        """Where decoded messages go."""

    async def start(self, bind: str = "tcp://127.0.0.1:0") -> str:
        """Listen on `bind`; return the real endpoint."""

    def send(self, address: str, kind: Kind, request_id: int, body: object) -> None:
        """Send a request or notification to the peer listening at `address`."""

    def reply(self, route: Route, request_id: int, body: object) -> None:
        """Answer the request `request_id` that came in on `route`."""

    async def forget(self, address: str) -> None:
        """Drop the link to `address`."""

    async def close(self) -> None:
        """Stop reading, close every socket, release the context."""


class ZmqTransport:
    """The `Transport` over pyzmq with `zmq.asyncio` (STYLE §5).

    Args:
        peer_id: this peer, written into every envelope's `sender`; a secure
            transport sends as the id its key speaks as (`Security.peer_id`),
            which is `peer_id` for a peer (an ephemeral client gets its owner's).
        clock: the peer's Lamport clock (a fresh one if omitted).
        context: a zmq.asyncio context to share; by default the transport owns one.
        max_message_size: larger messages are dropped and counted.
        shaper: optional simulated latency/bandwidth per link (off by default).
        security: keys and trust list of a secure peer (None: an open peer).
    """

    def __init__(
        self,
        peer_id: PeerId,
        clock: LamportClock | None = None,
        *,
        context: zmq.asyncio.Context | None = None,
        max_message_size: int = DEFAULT_MAX_MESSAGE_SIZE,
        shaper: Shaper | None = None,
        security: Security | None = None,
    ) -> None:
        # Identity is the key (docs/design.md "Secure swarm"): others accept from
        # this key only the id it speaks as, so that is the one to send.
        self.peer_id = security.peer_id if security is not None else peer_id
        self.security = security
        self.clock = clock or LamportClock()
        self.stats = Stats()
        self.shaper = shaper
        self.max_message_size = max_message_size
        self._outbox = Outbox(self.stats, min(limits.FRAME_BYTES, max_message_size), shaper)
        self._receiver = Receiver(
            self.peer_id, self.clock, self.stats, max_message_size, security, self.reply
        )
        self._context = context
        self._owns_context = context is None
        self._router: zmq.asyncio.Socket | None = None
        self._dealers: dict[str, Link] = {}
        self._zap: curve.ZapHandler | None = None
        self._readers: set[asyncio.Task[None]] = set()
        self._address: str | None = None
        self._closed = False

    @property
    def address(self) -> str:
        """The bound endpoint, e.g. tcp://127.0.0.1:43121 (after `start`), with
        `#curve=KEY` when secure."""
        if self._address is None:
            raise RuntimeError("transport not started")
        return self._address

    @property
    def closed(self) -> bool:
        """True once `close()` began."""
        return self._closed

    def set_sink(self, sink: Sink) -> None:
        """Where decoded messages go (the RPC layer); set before `start`."""
        self._receiver.sink = sink

    @property
    def parts(self) -> parts.Reassembly:
        """The messages being received as parts, and their budget."""
        return self._receiver.parts

    async def start(self, bind: str = "tcp://127.0.0.1:0") -> str:
        """Bind the ROUTER and start reading.

        Args:
            bind: a zmq endpoint; port 0 (or *) picks a free port.

        Returns:
            The address peers connect to: the bound endpoint (LAST_ENDPOINT), and
            when secure its public key.

        Raises:
            NetworkError: the address cannot be bound.
        """
        if self._router is not None or self._closed:
            raise RuntimeError("transport already started or closed")
        if self._context is None:
            self._context = zmq.asyncio.Context()
        router = self._socket(zmq.ROUTER)
        try:
            if self.security is not None:
                self._serve_zap(self._context, self.security)
                curve.secure_router(router, self.security)
            router.bind(bind)
        except zmq.ZMQError as exc:
            router.close(linger=0)
            raise NetworkError(
                f"cannot listen on {bind}: {exc}",
                advice="act: pick a free port, or port 0 for any (`mapctl peer start --listen`)",
            ) from exc
        self._router = router
        endpoint = router.getsockopt_string(zmq.LAST_ENDPOINT)
        if self.security is not None:
            endpoint = keyed_address(endpoint, self.security.keys.public)
        self._address = endpoint
        if self.security is None:
            self._spawn(self._read(router, self._receiver.on_router), f"router {self._address}")
        else:  # frames, not bytes: each carries the key of its connection
            reader = self._read(router, self._on_secure_router_frames, copy=False)
            self._spawn(reader, f"router {self._address}")
        log.debug("peer %s listening on %s", self.peer_id.short, self._address)
        return self._address

    def send(self, address: str, kind: Kind, request_id: int, body: object) -> None:
        """Stamp, encode and send a request or notification (never waits).

        Raises:
            PeerUnavailable: the transport is closed.
            UsageError: `address` is not a valid zmq endpoint (a ValueError).
            ProtocolError: the encoded message exceeds `max_message_size`.
        """
        if self._closed:
            raise PeerUnavailable(f"cannot reach {address}: the transport is closed")
        data = self._stamp(kind, request_id, body)
        if len(data) > self.max_message_size:
            raise ProtocolError(
                f"message of {len(data)} bytes exceeds the limit of {self.max_message_size}",
                advice="act: send less at once (split the commit or the import)",
            )
        self._outbox.send(self._dealer(address), data, address, codec.body_name(body))

    def reply(self, route: Route, request_id: int, body: object) -> None:
        """Answer a request on the ROUTER (never waits; dropped by zmq if the peer left).

        Raises:
            PeerUnavailable: the transport is closed.
        """
        if self._closed or self._router is None:
            raise PeerUnavailable(f"cannot answer {route.peer}: the transport is closed")
        data = self._stamp(Kind.REPLY, request_id, body)
        if len(data) > self.max_message_size:
            body = ErrorReply(ProtocolError.code, f"reply of {len(data)} bytes is too large")
            data = self._stamp(Kind.REPLY, request_id, body)
        self._outbox.send(self._router, data, route.peer, codec.body_name(body), [route.routing_id])

    async def forget(self, address: str) -> None:
        """Close the link to `address` (a peer that left); a later send reopens it."""
        link = self._dealers.pop(address, None)
        if link is not None:
            for task in link.tasks:
                task.cancel()
            await asyncio.gather(*link.tasks, return_exceptions=True)
            link.close()

    async def close(self) -> None:
        """Cancel and await the readers, close every socket (LINGER=0), end the context."""
        if self._closed:
            return
        self._closed = True
        self._receiver.closed = True
        self._outbox.cancel()
        readers = list(self._readers)
        for task in readers:
            task.cancel()
        await asyncio.gather(*readers, return_exceptions=True)
        for link in self._dealers.values():
            link.close()
        self._dealers.clear()
        if self._router is not None:
            self._router.close(linger=0)
        if self._zap is not None:
            self._zap.stop()
        if self._owns_context and self._context is not None:
            self._context.term()
        log.debug("peer %s transport closed", self.peer_id.short)

    # -- sending -------------------------------------------------------------

    def _stamp(self, kind: Kind, request_id: int, body: object) -> bytes:
        env = Envelope(request_id, self.peer_id, self.clock.tick(), kind, body)
        return codec.encode(env)

    def _socket(self, kind: int) -> zmq.asyncio.Socket:
        assert self._context is not None
        sock = self._context.socket(kind)
        sock.setsockopt(zmq.LINGER, 0)
        # Hard caps against memory exhaustion (issue 18 §5): libzmq refuses a larger
        # frame on its header, before allocating it, and queues few frames per
        # connection; below them the receiver drops and counts.
        sock.setsockopt(zmq.MAXMSGSIZE, self._outbox.frame_bytes * _HARD_LIMIT_FACTOR)
        sock.setsockopt(zmq.RCVHWM, limits.RECEIVE_QUEUE)
        return sock

    def _dealer(self, address: str) -> zmq.asyncio.Socket:
        link = self._dealers.get(address)
        if link is not None:
            return link.sock
        if self._context is None:
            raise RuntimeError("transport not started")
        if len(self._dealers) >= limits.MAX_LINKS:
            # Addresses come from other peers (a hostile one may name thousands):
            # close the oldest link rather than run out of file descriptors.
            self._close_link(next(iter(self._dealers)))
        link = Link.open(lambda: self._socket(zmq.DEALER), address, self.security)
        key = split_address(address)[1] if self.security is not None else None
        link.tasks = (
            self._spawn(
                self._read(
                    link.sock, lambda frames: self._receiver.on_dealer(address, frames, key)
                ),
                f"dealer {address}",
            ),
            self._spawn(
                link.watch(self.security, lambda error: self._refused(address, error)),
                f"handshakes {address}",
            ),
        )
        self._dealers[address] = link
        return link.sock

    def _refused(self, address: str, error: AccessRefused) -> None:
        """Drop a link that can never work and fail what waits on it; the next
        send to `address` tries again on a fresh link (trust may have changed)."""
        log.info("link to %s refused: %s", address, error)
        link = self._dealers.pop(address, None)
        if link is not None:
            for task in link.tasks:
                if task is not asyncio.current_task():
                    task.cancel()
            link.close()
        self._receiver.parts.forget(address)
        if self._receiver.sink is not None:
            self._receiver.sink.on_link_refused(address, error)

    def _serve_zap(self, context: zmq.asyncio.Context, security: Security) -> None:
        zap = curve.ZapHandler(context, security)
        zap.start()
        self._zap = zap
        self._spawn(zap.serve(), "zap")

    def _close_link(self, address: str) -> None:
        """Drop the link to `address` now: its tasks stop, then its socket closes
        (requests still waiting on it time out)."""
        link = self._dealers.pop(address)
        for task in link.tasks:
            task.cancel()
        if link.tasks:
            link.tasks[0].add_done_callback(lambda _: link.close())
        else:
            link.close()
        log.debug("closed the link to %s (more than %d links)", address, limits.MAX_LINKS)

    # -- receiving -----------------------------------------------------------

    def _spawn(self, coro: Coroutine[Any, Any, None], name: str) -> asyncio.Task[None]:
        task = asyncio.get_running_loop().create_task(coro, name=name)
        self._readers.add(task)
        task.add_done_callback(self._reader_done)
        return task

    def _reader_done(self, task: asyncio.Task[None]) -> None:
        self._readers.discard(task)
        if not task.cancelled() and task.exception() is not None:
            log.error("reader %s stopped", task.get_name(), exc_info=task.exception())

    async def _read(
        self, sock: zmq.asyncio.Socket, handle: Callable[[list[Any]], None], copy: bool = True
    ) -> None:
        # One awaited receive (the "poll"), then non-blocking receives through a
        # plain shadow of the same socket while ZMQ_EVENTS says more is queued: a
        # batch costs no futures. The next awaited receive re-checks ZMQ_EVENTS
        # itself, so no edge of zmq's edge-triggered fd is lost.
        shadow: zmq.Socket[bytes] = zmq.Socket.shadow(sock.underlying)
        while True:
            frames: list[Any] = await sock.recv_multipart(copy=copy)
            self._dispatch(handle, frames)
            for _ in range(_BATCH):
                if not cast(int, shadow.getsockopt(_EVENTS)) & _POLLIN:
                    break
                self._dispatch(handle, shadow.recv_multipart(_NOBLOCK, copy=copy))
            else:
                # A full batch: let other tasks run (awaiting a receive that can
                # complete at once would not yield to them).
                await asyncio.sleep(0)

    def _dispatch(self, handle: Callable[[list[Any]], None], frames: list[Any]) -> None:
        try:
            handle(frames)
        except Exception:  # a bug in one message's handling must not stop the reader
            log.exception("peer %s failed to dispatch a message", self.peer_id.short)

    def _on_secure_router_frames(self, frames: list[zmq.Frame]) -> None:
        # libzmq stamps every message with the ZAP User-Id of its connection,
        # which `curve.ZapHandler` makes the client's public key in hex.
        user = frames[-1].get(_USER_ID) if len(frames) > 1 else None
        key = bytes.fromhex(str(user)) if user else None
        self._receiver.on_router([f.bytes for f in frames], key)
