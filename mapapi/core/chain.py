"""Verifiable history: each commit of a chunk links to the one before, as git's do
(issue 18, part 3). Pure: hashing only.

A link is SHA-256 over the previous link and a canonical encoding of the commit
as it touched the chunk: its record (id, time, author, message) and its
revisions of that chunk in item order (item, times, removal, author, and the
payload's own digest). Holders that applied the same log hold the same head;
a flipped byte in a stored payload, a dropped commit or a rolled-back file
changes every link after it, so comparing heads, or recomputing the chain
from the stored revisions (`mapctl fsck`), finds it.
"""

from __future__ import annotations

import hashlib
import struct
from collections.abc import Iterable, Sequence

from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId

GENESIS = bytes(32)
"""The link before a chunk's first commit."""


def link(
    previous: bytes, chunk: ChunkId, record: CommitRecord, revisions: Sequence[Revision]
) -> bytes:
    """The chain's next link after `previous`, for `record`'s revisions of `chunk`."""
    h = hashlib.sha256(previous)
    h.update(chunk.to_bytes())
    h.update(record.id.to_bytes())
    h.update(struct.pack(">Q", record.time))
    h.update(record.author.to_bytes())
    _text(h, record.message)
    for r in sorted((r for r in revisions if r.chunk_id == chunk), key=lambda r: r.item_id):
        h.update(r.item_id.to_bytes())
        h.update(struct.pack(">QQ?", r.insert_time, r.update_time, r.removed))
        h.update(r.author.to_bytes())
        _text(h, r.table)
        h.update(hashlib.sha256(r.data).digest())
    return h.digest()


def replay(
    chunk: ChunkId, commits: Iterable[tuple[CommitRecord, Sequence[Revision]]]
) -> list[bytes]:
    """Every link of a chunk's chain, from its commits in log (time) order."""
    links: list[bytes] = []
    previous = GENESIS
    for record, revisions in commits:
        previous = link(previous, chunk, record, revisions)
        links.append(previous)
    return links


def _text(h: hashlib._Hash, text: str) -> None:
    data = text.encode("utf-8")
    h.update(struct.pack(">I", len(data)))  # length first: "ab"+"c" and "a"+"bc" differ
    h.update(data)
