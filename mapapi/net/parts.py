"""Large messages as parts, and the budget of what is being reassembled (issue 18 §5).

libzmq holds a frame whole in memory before it hands it over, and `zmq.MAXMSGSIZE`
applies per frame. With one frame per message, 20 senders of one 120 MB frame
each held 20 x 120 MB in the receiver before it could refuse anything. So the
transport sends a message over `limits.FRAME_BYTES` as a run of parts, each a
two-frame zmq message `[header, chunk]`, and caps frames at twice that size:
libzmq then buffers little per connection, and what is reassembled is counted
here, per connection (one transfer at a time, at most `max_message` bytes) and in
total (`budget`), before a byte of it is kept. Pure: no zmq, time is a parameter.
"""

from __future__ import annotations

import struct
from collections.abc import Hashable, Iterator
from dataclasses import dataclass, field

_HEADER = struct.Struct(">4sQQQ")  # magic, transfer id, total bytes, offset of the chunk
_MAGIC = b"mpt1"
MAX_TRANSFERS = 4_096
"""Connections with a transfer under way (or refused, its parts still coming)
kept at once; beyond, the oldest is dropped (its reservation released)."""


def is_part_header(frame: bytes) -> bool:
    """Whether `frame` is the header of a part (the first frame of a part message)."""
    return len(frame) == _HEADER.size and frame[:4] == _MAGIC


def header(transfer_id: int, total: int, offset: int) -> bytes:
    """The header of the part at `offset` of a transfer of `total` bytes."""
    return _HEADER.pack(_MAGIC, transfer_id, total, offset)


def split(data: bytes, transfer_id: int, part_bytes: int) -> Iterator[list[bytes]]:
    """The part messages `[header, chunk]` that carry `data`, in order."""
    view = memoryview(data)
    total = len(data)
    for offset in range(0, total, part_bytes):
        yield [header(transfer_id, total, offset), bytes(view[offset : offset + part_bytes])]


@dataclass(frozen=True, slots=True)
class Refused:
    """A transfer the receiver will not hold: `reason` is the stats reason
    ("oversized", "over-budget", "malformed"); `first` the first chunk (whose
    envelope may tell the request id to answer)."""

    reason: str
    why: str
    first: bytes


@dataclass(slots=True)
class _Transfer:
    transfer_id: int
    total: int
    touched: float
    chunks: list[bytes] = field(default_factory=list)
    received: int = 0
    holds: bool = False  # it holds a reservation of `total` bytes
    refused: bool = False  # its later parts are skipped, not kept


class Reassembly:
    """Reassembles the parts that arrive on each connection, within a budget.

    Args:
        max_message: the largest message accepted (per connection, one at a time).
        budget: bytes of unfinished messages held over all connections.
        stall: seconds without a new part after which a transfer's reservation
            may be taken by another.
    """

    def __init__(self, max_message: int, budget: int, stall: float) -> None:
        self.max_message = max_message
        self.budget = budget
        self.stall = stall
        self.reserved = 0
        """Bytes reserved for the transfers under way (their declared totals)."""
        self.peak = 0
        """The most `reserved` ever was."""
        self._transfers: dict[Hashable, _Transfer] = {}

    def add(
        self, conn: Hashable, header: bytes, chunk: bytes, now: float
    ) -> bytes | Refused | None:
        """Take one part that came on `conn`.

        Returns:
            The whole message when this part completes it; `Refused` when this part
            starts (or breaks) a transfer that will not be held, once per transfer;
            None otherwise (more to come, or a part of a refused transfer).
        """
        _, transfer_id, total, offset = _HEADER.unpack(header)
        current = self._transfers.get(conn)
        if offset == 0:
            if current is not None:  # the sender gave up on the last one
                self._drop(conn, current)
            return self._start(conn, transfer_id, total, chunk, now)
        if current is None or current.transfer_id != transfer_id:
            return None  # the rest of a transfer dropped earlier: already counted
        if current.refused:
            if offset + len(chunk) >= current.total:
                self._drop(conn, current)
            return None
        if offset != current.received or total != current.total:
            return self._refuse(conn, current, "malformed", "a part out of order", chunk)
        return self._append(conn, current, chunk, now)

    def forget(self, conn: Hashable) -> None:
        """Drop what `conn` was sending (the connection is gone)."""
        current = self._transfers.get(conn)
        if current is not None:
            self._drop(conn, current)

    def _start(
        self, conn: Hashable, transfer_id: int, total: int, chunk: bytes, now: float
    ) -> bytes | Refused | None:
        transfer = _Transfer(transfer_id, total, now)
        if len(self._transfers) >= MAX_TRANSFERS:
            oldest = next(iter(self._transfers))
            self._drop(oldest, self._transfers[oldest])
        self._transfers[conn] = transfer
        if total > self.max_message:
            why = f"oversized message ({total} bytes, the limit is {self.max_message})"
            return self._refuse(conn, transfer, "oversized", why, chunk)
        if self.reserved + total > self.budget:
            self._release_stalled(now)
        if self.reserved + total > self.budget:
            why = (
                f"busy: {self.reserved} bytes of other messages are being received "
                f"(budget {self.budget}); send it again later"
            )
            return self._refuse(conn, transfer, "over-budget", why, chunk)
        self.reserved += total
        transfer.holds = True
        self.peak = max(self.peak, self.reserved)
        return self._append(conn, transfer, chunk, now)

    def _append(
        self, conn: Hashable, transfer: _Transfer, chunk: bytes, now: float
    ) -> bytes | Refused | None:
        if transfer.received + len(chunk) > transfer.total:
            return self._refuse(conn, transfer, "malformed", "parts beyond the total", chunk)
        transfer.chunks.append(chunk)
        transfer.received += len(chunk)
        transfer.touched = now
        if transfer.received < transfer.total:
            return None
        self._drop(conn, transfer)
        return b"".join(transfer.chunks)

    def _refuse(
        self, conn: Hashable, transfer: _Transfer, reason: str, why: str, chunk: bytes
    ) -> Refused:
        first = transfer.chunks[0] if transfer.chunks else chunk
        self._release(transfer)
        transfer.refused, transfer.chunks = True, []
        if transfer.total <= len(chunk):
            self._transfers.pop(conn, None)  # a single part: nothing more will come
        return Refused(reason, why, first)

    def _release(self, transfer: _Transfer) -> None:
        if transfer.holds:
            self.reserved -= transfer.total
            transfer.holds = False

    def _drop(self, conn: Hashable, transfer: _Transfer) -> None:
        self._release(transfer)
        self._transfers.pop(conn, None)

    def _release_stalled(self, now: float) -> None:
        for conn, transfer in list(self._transfers.items()):
            if transfer.holds and now - transfer.touched > self.stall:
                self._drop(conn, transfer)
