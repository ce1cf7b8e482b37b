"""Traffic counters: bytes and messages per peer and message type, in and out.

The transport records every message it sends or receives here, and every one it
drops (malformed, oversized, unexpected, ...) under a reason. Benchmarks read
the totals (paper Fig. 6 compares bytes of triggers against polling), and
`snapshot()` gives a JSON-ready view for `mapctl --json`.

A peer key is the remote's address for links this peer opened (its requests and
the replies to them) and the remote's PeerId for links the remote opened. Once
a table holds `limits.MAX_STATS_KEYS` keys, new peers are counted together
under `OTHERS`, so senders with ever new ids cannot grow it without bound.
"""

from __future__ import annotations

from dataclasses import dataclass

from mapapi.core import limits

OTHERS = "(others)"
"""The peer key of traffic from peers beyond `limits.MAX_STATS_KEYS`."""


@dataclass(slots=True)
class Traffic:
    """A message count and their total size in bytes."""

    messages: int = 0
    bytes: int = 0

    def add(self, size: int) -> None:
        """Count one message of `size` bytes."""
        self.messages += 1
        self.bytes += size


def _bump(table: dict[tuple[str, str], Traffic], key: tuple[str, str], size: int) -> None:
    t = table.get(key)
    if t is None:
        if len(table) >= limits.MAX_STATS_KEYS:  # strangers with ever new ids
            key = (OTHERS, key[1])
            t = table.get(key)
        if t is None:
            t = table[key] = Traffic()
    t.messages += 1
    t.bytes += size


def _sum(table: dict[tuple[str, str], Traffic], pick: int) -> dict[str, Traffic]:
    out: dict[str, Traffic] = {}
    for key, t in table.items():
        total = out.setdefault(key[pick], Traffic())
        total.messages += t.messages
        total.bytes += t.bytes
    return out


class Stats:
    """Counters of one transport. Cheap to update: one dict lookup per message."""

    def __init__(self) -> None:
        self.sent: dict[tuple[str, str], Traffic] = {}
        """(peer, message type) -> traffic sent."""
        self.received: dict[tuple[str, str], Traffic] = {}
        """(peer, message type) -> traffic received and decoded."""
        self.dropped: dict[tuple[str, str], Traffic] = {}
        """(peer, reason) -> messages received but not delivered."""

    def record_sent(self, peer: str, msg_type: str, size: int) -> None:
        """Count a message handed to the socket (after shaping, if any)."""
        _bump(self.sent, (peer, msg_type), size)

    def record_received(self, peer: str, msg_type: str, size: int) -> None:
        """Count a message received and decoded."""
        _bump(self.received, (peer, msg_type), size)

    def record_dropped(self, peer: str, reason: str, size: int) -> None:
        """Count a message that was not delivered, under `reason` (e.g. "malformed")."""
        _bump(self.dropped, (peer, reason), size)

    def sent_by_type(self) -> dict[str, Traffic]:
        """Traffic sent, summed over peers."""
        return _sum(self.sent, 1)

    def received_by_type(self) -> dict[str, Traffic]:
        """Traffic received, summed over peers."""
        return _sum(self.received, 1)

    def sent_by_peer(self) -> dict[str, Traffic]:
        """Traffic sent, summed over message types."""
        return _sum(self.sent, 0)

    def received_by_peer(self) -> dict[str, Traffic]:
        """Traffic received, summed over message types."""
        return _sum(self.received, 0)

    def dropped_by_reason(self) -> dict[str, Traffic]:
        """Dropped messages, summed over peers."""
        return _sum(self.dropped, 1)

    def dropped_count(self, reason: str | None = None) -> int:
        """How many messages were dropped, for one reason or in total."""
        return sum(
            t.messages for (_, r), t in self.dropped.items() if reason is None or r == reason
        )

    def reset(self) -> None:
        """Zero every counter (between benchmark phases)."""
        self.sent.clear()
        self.received.clear()
        self.dropped.clear()

    def snapshot(self) -> dict[str, dict[str, dict[str, int]]]:
        """All counters as plain dicts: {"sent"|"received"|"dropped": {key: {...}}}.

        Keys are "peer/type" (or "peer/reason"); values hold messages and bytes.
        """

        def flat(table: dict[tuple[str, str], Traffic]) -> dict[str, dict[str, int]]:
            return {
                f"{peer}/{name}": {"messages": t.messages, "bytes": t.bytes}
                for (peer, name), t in sorted(table.items())
            }

        return {
            "sent": flat(self.sent),
            "received": flat(self.received),
            "dropped": flat(self.dropped),
        }
