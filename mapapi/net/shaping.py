"""Simulated link latency and bandwidth, for experiments (off by default).

Paper Fig. 7 compares decentralized and centralized registration under limited
bandwidth; loopback has neither latency nor a bandwidth limit, so the transport
can hold each outgoing message back by what a real link would take:

    departure = max(now, link busy until) + size / bandwidth
    arrival   = departure + latency

A link transmits one message at a time (its `busy_until` moves forward), so a
burst of large messages queues like it would on a slow radio. The arithmetic is
pure (`schedule`); `Shaper` only keeps each link's `busy_until`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class LinkShape:
    """How one link behaves.

    Attributes:
        latency: one-way delay in seconds added to every message.
        bandwidth: bytes per second, or None for unlimited.
    """

    latency: float = 0.0
    bandwidth: float | None = None

    def __post_init__(self) -> None:
        if not (self.latency >= 0 and math.isfinite(self.latency)):
            raise ValueError(f"latency must be a finite number >= 0, got {self.latency}")
        if self.bandwidth is not None and not self.bandwidth > 0:
            raise ValueError(f"bandwidth must be > 0 bytes/s, got {self.bandwidth}")

    @property
    def is_null(self) -> bool:
        """True when the link adds no delay at all."""
        return self.latency == 0 and self.bandwidth is None


def schedule(now: float, busy_until: float, size: int, shape: LinkShape) -> tuple[float, float]:
    """When a message of `size` bytes sent at `now` arrives over a shaped link.

    Args:
        now: the send time (any monotonic clock, seconds).
        busy_until: when the link finishes transmitting what was sent before.
        size: the message size in bytes.
        shape: the link.

    Returns:
        (arrival time, the link's new busy_until).
    """
    start = max(now, busy_until)
    transmit = size / shape.bandwidth if shape.bandwidth is not None else 0.0
    departure = start + transmit
    return departure + shape.latency, departure


class Shaper:
    """Per-link shaping state for one transport.

    Args:
        default: the shape of every link not named in `links`.
        links: shapes for particular peer keys (an address or a PeerId, as in stats).
    """

    def __init__(
        self, default: LinkShape | None = None, links: dict[str, LinkShape] | None = None
    ) -> None:
        self.default = default or LinkShape()
        self.links: dict[str, LinkShape] = dict(links or {})
        self._busy_until: dict[str, float] = {}
        self._last_arrival: dict[str, float] = {}

    def set_link(self, peer: str, shape: LinkShape) -> None:
        """Shape the link to `peer` (replacing the default for it)."""
        self.links[peer] = shape

    def arrival(self, peer: str, size: int, now: float) -> float | None:
        """When a message of `size` bytes sent to `peer` at `now` should go out.

        Returns None for an unshaped link (send at once). Records the
        transmission, so the next message on the link queues behind it; arrival
        times on one link strictly increase, so timers fire in send order.
        """
        shape = self.links.get(peer, self.default)
        if shape.is_null:
            return None
        arrival, busy = schedule(now, self._busy_until.get(peer, now), size, shape)
        last = self._last_arrival.get(peer)
        if last is not None and arrival <= last:
            arrival = math.nextafter(last, math.inf)
        self._busy_until[peer] = busy
        self._last_arrival[peer] = arrival
        return arrival
