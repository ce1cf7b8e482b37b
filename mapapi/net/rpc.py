"""Requests with deadlines and concurrent handlers, over a `Transport`.

`request()` files a future under a fresh request id, sends, and awaits the reply under
`asyncio.timeout`; the transport's reader resolves the future. Handlers are registered per
body type. An `async def` handler runs as its own task (kept in a set, cancelled on close), so
one that waits for a lock never blocks the reader; a plain function runs inline in the reader,
which saves a task per message for answers that need no waiting (DESIGN §12). A handler raising
`MapError` answers `ErrorReply(code, message)`, which the requester raises again as the same
class (STYLE §4); any other exception is logged and answered with a generic `MapError`.
"""

from __future__ import annotations

import asyncio
import inspect
import itertools
import logging
from collections.abc import Callable, Hashable
from dataclasses import dataclass
from typing import Any, TypeVar, overload

from mapapi.core.errors import (
    AccessRefused,
    MapError,
    PeerUnavailable,
    ProtocolError,
    RequestTimeout,
)
from mapapi.core.ids import PeerId
from mapapi.net import codec
from mapapi.net.codec import ErrorReply, Kind
from mapapi.net.transport import Inbound, Transport

log = logging.getLogger(__name__)

T = TypeVar("T")
K = TypeVar("K", bound=Hashable)

DEFAULT_TIMEOUT = 5.0
"""Seconds a request waits for its reply unless told otherwise (DESIGN §11)."""
# What to do when this peer's own side closes (`peer stop`, a shutdown) under a request.
_CLOSING = "wait for this peer to stop, then start it again (`mapctl peer start --detach`)"


@dataclass(frozen=True, slots=True)
class Request:
    """An inbound request or notification, as a handler sees it."""

    sender: PeerId
    lamport: int
    request_id: int
    kind: Kind
    body: Any


Handler = Callable[[Request], Any]
"""`def h(req) -> body` (inline) or `async def h(req) -> body` (own task).

A notification's handler result is ignored.
"""


class Rpc:
    """Request/response and notifications between peers; owns its transport.

    Args:
        transport: the message transport (e.g. `ZmqTransport`), not yet started.
        default_timeout: deadline in seconds for `request()` without `timeout`.
        on_seen: told the sender of every message that arrives (proof of life).
    """

    def __init__(
        self,
        transport: Transport,
        *,
        default_timeout: float = DEFAULT_TIMEOUT,
        on_seen: Callable[[PeerId], None] | None = None,
    ) -> None:
        self.transport = transport
        self.default_timeout = default_timeout
        self._handlers: dict[type, Handler] = {}
        self._pending: dict[int, tuple[str, asyncio.Future[object]]] = {}
        self._from: dict[int, PeerId] = {}  # requests whose reply must come from this peer
        self._tasks: set[asyncio.Task[object]] = set()
        self._ids = itertools.count(1)
        self._closed = False
        self.on_seen = on_seen
        # Addresses of peers declared dead (`swarm/liveness.py`), with who answers there
        # ("peer robot2 (146ca670)"): requests to them fail at once, probes excepted.
        self.down: dict[str, str] = {}
        transport.set_sink(self)

    @property
    def address(self) -> str:
        """The endpoint other peers send requests to."""
        return self.transport.address

    @property
    def pending(self) -> int:
        """Requests sent and not yet answered."""
        return len(self._pending)

    @property
    def running_handlers(self) -> int:
        """Handler tasks still running."""
        return len(self._tasks)

    async def start(self, bind: str = "tcp://127.0.0.1:0") -> str:
        """Start the transport listening on `bind`; return the real endpoint."""
        return await self.transport.start(bind)

    def register(self, body_type: type, handler: Handler) -> None:
        """Serve requests whose body is a `body_type` with `handler`.

        Raises:
            TypeError: `body_type` is not a registered envelope body.
            ValueError: it already has a handler.
        """
        codec.body_name(body_type)
        if body_type in self._handlers:
            raise ValueError(f"{body_type.__name__} already has a handler")
        self._handlers[body_type] = handler

    @overload
    async def request(
        self,
        address: str,
        body: object,
        *,
        timeout: float | None = ...,  # noqa: ASYNC109
        expect: type[T],
        probe: bool = ...,
        sender: PeerId | None = ...,
    ) -> T: ...

    @overload
    async def request(
        self,
        address: str,
        body: object,
        *,
        timeout: float | None = ...,  # noqa: ASYNC109
        expect: None = ...,
        probe: bool = ...,
        sender: PeerId | None = ...,
    ) -> object: ...

    async def request(
        self,
        address: str,
        body: object,
        *,
        # A parameter rather than the caller's asyncio.timeout: every request gets a
        # deadline even when the caller sets none (DESIGN §11).
        timeout: float | None = None,  # noqa: ASYNC109
        expect: type[Any] | None = None,
        probe: bool = False,
        sender: PeerId | None = None,
    ) -> object:
        """Send `body` to the peer at `address` and return its reply body.

        Args:
            address: the remote's endpoint (its `Rpc.address`).
            body: a registered envelope body, e.g. `Ping()`.
            timeout: seconds to wait; `default_timeout` if None.
            expect: the reply body type; anything else raises ProtocolError.
            probe: send even to an address in `down` (a heartbeat).
            sender: the peer that must answer (another at the address: ProtocolError).

        Raises:
            RequestTimeout: no reply before the deadline (retriable).
            PeerUnavailable: this side closed before the reply came (retriable).
            MapError: the subclass named by the remote's ErrorReply code.
            ProtocolError: a malformed or unexpected reply.
        """
        if self._closed:
            raise PeerUnavailable(f"cannot reach {address}: this peer is closing", advice=_CLOSING)
        if address in self.down and not probe:
            raise PeerUnavailable(
                f"{self.down[address]} at {address} is down: it has not answered for a while"
            )
        deadline = self.default_timeout if timeout is None else timeout
        request_id = next(self._ids)
        fut: asyncio.Future[object] = asyncio.get_running_loop().create_future()
        self._pending[request_id] = (address, fut)
        if sender is not None:
            self._from[request_id] = sender
        try:
            async with asyncio.timeout(deadline):
                self.transport.send(address, Kind.REQUEST, request_id, body)
                reply = await fut
        except TimeoutError:
            name = codec.body_name(body)
            raise RequestTimeout(
                f"no reply from {address} to {name} within {deadline:g} s"
            ) from None
        finally:
            self._pending.pop(request_id, None)
            self._from.pop(request_id, None)
        if isinstance(reply, ErrorReply):
            raise codec.error_from_reply(reply)
        if expect is not None and not isinstance(reply, expect):
            raise ProtocolError(
                f"{address} answered {codec.body_name(reply)}, expected {codec.body_name(expect)}"
            )
        return reply

    def notify(self, address: str, body: object) -> None:
        """Send `body` one way (no reply, no delivery guarantee).

        Raises:
            PeerUnavailable: this side is closed.
        """
        if self._closed:
            raise PeerUnavailable(f"cannot reach {address}: this peer is closing", advice=_CLOSING)
        self.transport.send(address, Kind.NOTIFY, 0, body)

    async def forget(self, address: str) -> None:
        """Fail requests pending at `address` with PeerUnavailable and drop the link."""
        self._fail_pending(address, lambda: PeerUnavailable(f"{address} left before it answered"))
        await self.transport.forget(address)

    def _fail_pending(self, address: str, error: Callable[[], MapError]) -> None:
        for peer, fut in list(self._pending.values()):
            if peer == address and not fut.done():
                fut.set_exception(error())  # one instance each: raising adds a traceback

    def fail_pending(self, address: str, reason: str) -> None:
        """Fail the requests pending at `address` now with PeerUnavailable(`reason`)
        (it was declared dead: waiting out their deadlines would only stall)."""
        self._fail_pending(address, lambda: PeerUnavailable(reason))

    async def close(self, grace: float = 0.0) -> None:
        """Fail pending requests with PeerUnavailable, give running handlers up to
        `grace` seconds to answer (a handler that asked for the close, say), cancel
        the rest, then close the transport. Idempotent."""
        if self._closed:
            return
        self._closed = True
        running = [t for t in self._tasks if t is not asyncio.current_task()]
        if grace > 0 and running:
            await asyncio.wait(running, timeout=grace)
        for address, fut in self._pending.values():
            if not fut.done():
                fut.set_exception(
                    PeerUnavailable(f"closed while waiting for {address}", advice=_CLOSING)
                )
        tasks = [t for t in self._tasks if t is not asyncio.current_task()]
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        await self.transport.close()

    # -- Sink: called by the transport's readers, never awaits ----------------

    def on_message(self, msg: Inbound) -> None:
        """Resolve a pending request, or run the handler of a request/notification."""
        env = msg.envelope
        if self.on_seen is not None:
            self.on_seen(env.sender)
        if env.kind is Kind.REPLY:
            entry = self._pending.get(env.request_id)
            if entry is None or entry[0] != msg.address or entry[1].done():
                # late (after its deadline) or not ours
                self.transport.stats.record_dropped(str(msg.address), "unmatched", msg.size)
                return
            want = self._from.get(env.request_id)
            if want is not None and env.sender != want:
                who = f"{msg.address} answered as peer {env.sender.short}, not {want.short}"
                entry[1].set_exception(ProtocolError(who))
                return
            entry[1].set_result(env.body)
            return
        assert msg.route is not None
        handler = self._handlers.get(type(env.body))
        if handler is None or self._closed:
            self.transport.stats.record_dropped(msg.route.peer, "unhandled", msg.size)
            why = f"peer {self.transport.peer_id.short} does not serve {env.body_name}"
            self._answer(msg, ErrorReply(ProtocolError.code, why))
            return
        request = Request(env.sender, env.lamport, env.request_id, env.kind, env.body)
        try:
            result = handler(request)
        except Exception as exc:
            self._answer(msg, self._failure(msg, exc))
            return
        if inspect.isawaitable(result):
            # The task runs the handler's coroutine itself: if close() cancels it before
            # its first step the coroutine is closed (a wrapper would drop it unawaited).
            task = asyncio.ensure_future(result)
            task.set_name(f"rpc {env.body_name} from {msg.route.peer}")
            self._tasks.add(task)
            task.add_done_callback(self._tasks.discard)
            task.add_done_callback(lambda done: self._served(msg, done))
        else:
            self._answer(msg, result)

    def on_broken_reply(self, address: str, request_id: int, error: ProtocolError) -> None:
        """Fail the pending request whose reply could not be decoded."""
        entry = self._pending.get(request_id)
        if entry is not None and entry[0] == address and not entry[1].done():
            entry[1].set_exception(error)

    def on_link_refused(self, address: str, error: AccessRefused) -> None:
        """Fail every request pending at `address`: its link can never work."""
        self._fail_pending(address, lambda: type(error)(str(error)))

    # -- serving ---------------------------------------------------------------

    def _served(self, msg: Inbound, task: asyncio.Task[object]) -> None:
        if task.cancelled():
            return  # closing: the requester's own deadline covers it
        try:
            result = task.result()
        except Exception as exc:
            result = self._failure(msg, exc)
        self._answer(msg, result)

    def _failure(self, msg: Inbound, exc: Exception) -> ErrorReply:
        env = msg.envelope
        if isinstance(exc, MapError):
            return codec.error_reply(exc)
        log.error(
            "handler for %s from %s failed",
            env.body_name,
            env.sender.short,
            exc_info=(type(exc), exc, exc.__traceback__),
        )
        return ErrorReply(
            MapError.code, f"internal error handling {env.body_name}: {type(exc).__name__}: {exc}"
        )

    def _answer(self, msg: Inbound, result: object) -> None:
        env = msg.envelope
        if env.kind is not Kind.REQUEST or msg.route is None:
            return  # notifications are never answered
        try:
            self.transport.reply(msg.route, env.request_id, result)
        except PeerUnavailable:
            pass  # closing: the requester's own deadline covers it
        except TypeError:
            log.error("handler for %s returned %r, not a message body", env.body_name, result)
            why = f"internal error handling {env.body_name}: bad reply type"
            self.transport.reply(msg.route, env.request_id, ErrorReply(MapError.code, why))
