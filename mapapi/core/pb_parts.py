"""A big serialized protobuf message, cut at its top-level fields into parts.

The protobuf runtime parses or serializes a whole message in one call that
keeps the interpreter lock all along: about 30-60 ms for the snapshot of a
chunk of 20,000-100,000 rows on the project's 2-core machine, during which a
peer's event loop, in another thread, cannot run at all (issue 14 §1). The
wire format allows parts: a message's serialization is its fields one after
another, and the concatenation of two serializations of one message type
parses as their merge (repeated fields appended, scalars last-wins). So a
writer serializes such a message in parts and joins the bytes, and a reader
cuts the bytes at field boundaries (`parts`) and merges them one by one
(`Message.MergeFromString`); each call then holds the lock for a part only,
and the bytes are those of the message serialized whole.
"""

from __future__ import annotations

from collections.abc import Iterator

PART_BYTES = 256 * 1024
"""About how many bytes each part holds (a millisecond or two of parsing)."""

_FIXED = {1: 8, 5: 4}  # wire types 1 (64-bit) and 5 (32-bit): their sizes


def _varint(data: bytes, pos: int) -> tuple[int, int]:
    """The varint at `pos`, and the position after it."""
    value = shift = 0
    while True:
        if pos >= len(data) or shift > 63:
            raise ValueError("a varint runs past the end of the message")
        byte = data[pos]
        pos += 1
        value |= (byte & 0x7F) << shift
        if not byte & 0x80:
            return value, pos
        shift += 7


def parts(data: bytes, size: int = PART_BYTES) -> Iterator[bytes]:
    """`data` (a serialized message) in parts of whole top-level fields, each of
    about `size` bytes or one field; their merge is the message.

    Raises:
        ValueError: `data` is not a sequence of well-formed fields.
    """
    start = pos = 0
    view = memoryview(data)
    while pos < len(data):
        tag, pos = _varint(data, pos)
        wire = tag & 7
        if wire == 0:
            _, pos = _varint(data, pos)
        elif wire == 2:
            length, pos = _varint(data, pos)
            pos += length
        elif wire in _FIXED:
            pos += _FIXED[wire]
        else:
            raise ValueError(f"field {tag >> 3} has wire type {wire}, not one a message holds")
        if pos > len(data):
            raise ValueError(f"field {tag >> 3} runs past the end of the message")
        if pos - start >= size:
            yield bytes(view[start:pos])
            start = pos
    if start < len(data):
        yield bytes(view[start:])
