"""What the transport sends: one zmq message, or parts, shaped as one unit.

`Outbox` turns one encoded message into the zmq messages that carry it (itself,
or its parts of `frame_bytes` each, `mapapi.net.parts`, so a receiver never has
to hold a large frame whole), delays them when link shaping is on, and hands
them to the socket in order. It never awaits: zmq.asyncio sends at once when it
can and otherwise queues the send.
"""

from __future__ import annotations

import asyncio
import itertools
import logging
from collections.abc import Callable
from functools import partial
from typing import cast

import zmq.asyncio

from mapapi.net import parts
from mapapi.net.shaping import Shaper
from mapapi.net.stats import Stats

log = logging.getLogger(__name__)


class Outbox:
    """Sends the transport's messages (see the module doc).

    Args:
        stats: where sent messages are counted.
        frame_bytes: a larger message leaves as parts of this size.
        shaper: optional simulated latency/bandwidth per link.
    """

    def __init__(self, stats: Stats, frame_bytes: int, shaper: Shaper | None) -> None:
        self.stats = stats
        self.frame_bytes = frame_bytes
        self.shaper = shaper
        self._transfer_ids = itertools.count(1)
        self._timers: set[asyncio.TimerHandle] = set()

    def send(
        self,
        sock: zmq.asyncio.Socket,
        data: bytes,
        peer: str,
        msg_type: str,
        head: list[bytes] | None = None,
    ) -> None:
        """Send the message `data` to `peer` on `sock`, each zmq message prefixed
        with `head` (a ROUTER's routing id)."""
        messages = [(head or []) + frames for frames in self._frames(data)]
        size = len(data)
        if self.shaper is not None:
            loop = asyncio.get_running_loop()
            at = self.shaper.arrival(peer, size, loop.time())
            if at is not None:
                self._later(loop, at, partial(self._transmit, sock, messages, peer, msg_type, size))
                return
        self._transmit(sock, messages, peer, msg_type, size)

    def cancel(self) -> None:
        """Drop what shaping still delays (the transport closes)."""
        for handle in self._timers:
            handle.cancel()
        self._timers.clear()

    def _frames(self, data: bytes) -> list[list[bytes]]:
        if len(data) <= self.frame_bytes:
            return [[data]]
        return list(parts.split(data, next(self._transfer_ids), self.frame_bytes))

    def _later(
        self, loop: asyncio.AbstractEventLoop, when: float, send: Callable[[], None]
    ) -> None:
        def fire() -> None:
            self._timers.discard(handle)
            send()

        handle = loop.call_at(when, fire)
        self._timers.add(handle)

    def _transmit(
        self,
        sock: zmq.asyncio.Socket,
        messages: list[list[bytes]],
        peer: str,
        msg_type: str,
        size: int,
    ) -> None:
        if sock.closed:
            return
        # zmq.asyncio sends at once when it can and otherwise queues the send in
        # order (parts stay in sequence); the returned future is only watched
        # for failures.
        for frames in messages:
            fut = cast("asyncio.Future[object]", sock.send_multipart(frames, copy=True))
            if fut.done():
                _report_send(fut)
            else:
                fut.add_done_callback(_report_send)
        self.stats.record_sent(peer, msg_type, size)


def _report_send(fut: asyncio.Future[object]) -> None:
    if not fut.cancelled() and fut.exception() is not None:
        log.warning("send failed: %s", fut.exception())
