"""An outgoing link of the transport: one DEALER to one remote address (DESIGN §10).

`Link.open` connects the DEALER, secure or not as the address and this peer's
`Security` say (`mapapi.net.curve`), with a handshake monitor; `watch` reads that
monitor until the first handshake completes, then closes it (a monitor costs
two inproc sockets, and a swarm in one process has a link per pair of peers),
or until `LinkWatch` finds that the link can never work.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from dataclasses import dataclass

import zmq
import zmq.asyncio
from zmq.utils.monitor import parse_monitor_message

from mapapi.core.errors import AccessRefused, UsageError
from mapapi.net import curve
from mapapi.net.security import Security, split_address


@dataclass(slots=True)
class Link:
    """A DEALER, the tasks that serve it, and its handshake monitor while watched."""

    sock: zmq.asyncio.Socket
    endpoint: str
    tasks: tuple[asyncio.Task[None], ...] = ()
    monitor: zmq.asyncio.Socket | None = None

    @classmethod
    def open(
        cls, dealer: Callable[[], zmq.asyncio.Socket], address: str, security: Security | None
    ) -> Link:
        """Connect a DEALER made by `dealer()` to the peer at `address`, watched.

        Raises:
            AccessRefused: the two peers cannot talk (`curve.check_link`).
            UsageError: `address` is not a peer address.
        """
        endpoint, key = split_address(address)
        curve.check_link(address, endpoint, key, security)
        sock = dealer()
        if security is not None and key is not None:
            curve.secure_dealer(sock, security, key)
        link = cls(sock, endpoint, monitor=sock.get_monitor_socket(curve.WATCHED_EVENTS))
        try:
            sock.connect(endpoint)
        except zmq.ZMQError as exc:
            link.close()
            # A UsageError is a ValueError and a MapError: callers that handle a
            # peer that cannot be reached handle an address from the wire that
            # zmq refuses too.
            raise UsageError(f"not a peer address: {address!r} ({exc})") from exc
        return link

    async def watch(
        self, security: Security | None, refused: Callable[[AccessRefused], None]
    ) -> None:
        """Read the monitor until the first handshake completes (then stop
        watching), or until the link is refused for good (then call `refused`)."""
        monitor = self.monitor
        assert monitor is not None, "watched once, from `open`"
        judge = curve.LinkWatch(self.endpoint, security)
        while True:
            event = parse_monitor_message(await monitor.recv_multipart())
            error = judge.on_event(int(event["event"]), int(event["value"]))
            if error is not None:
                refused(error)
                return
            if judge.succeeded:
                self.unwatch()  # the link works: later reconnections need no watching
                return

    def unwatch(self) -> None:
        """Stop monitoring the handshakes."""
        if self.monitor is not None:
            self.sock.disable_monitor()
            self.monitor.close(linger=0)
            self.monitor = None

    def close(self) -> None:
        """Close the sockets (cancel the tasks first)."""
        self.unwatch()
        self.sock.close(linger=0)
