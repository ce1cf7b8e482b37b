"""Verifiable history: each commit of a chunk links to the one before, as git's do
(issue 18, part 3). Pure: hashing only.

A link is SHA-256 over the previous link and a canonical encoding of the commit
as it touched the chunk: its record (id, time, author, message) and its
revisions of that chunk in item order (item, times, removal, author, and the
payload's own digest). The store extends the chain of every chunk a commit
wrote as it applies the commit (`Store.apply_commit`, whichever path brought
it), so holders that applied the same commits hold the same head; a flipped
byte in a stored payload, a dropped commit or a rolled-back file changes every
link after it, so comparing heads, or recomputing the chain
from the stored revisions (`mapctl fsck`), finds it.
"""

from __future__ import annotations

import hashlib
import struct
from collections.abc import Callable, Iterable, Mapping, Sequence

from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, CommitId

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
    chunk: ChunkId,
    commits: Iterable[tuple[CommitRecord, Sequence[Revision]]],
    start: bytes = GENESIS,
) -> list[bytes]:
    """Every link of a chunk's chain, from its commits in log (time) order, after
    the link `start` (the chain's beginning by default)."""
    links: list[bytes] = []
    previous = start
    for record, revisions in commits:
        previous = link(previous, chunk, record, revisions)
        links.append(previous)
    return links


def extend(
    head_of: Callable[[ChunkId], bytes | None],
    record: CommitRecord,
    revisions: Sequence[Revision],
    chunks: Iterable[ChunkId] | None = None,
) -> list[tuple[ChunkId, bytes]]:
    """The links one applied commit adds: one per chunk it wrote revisions of
    (of those among `chunks`, if given), in chunk order, each after the chunk's
    head (`head_of`, None before its first commit)."""
    wrote = {r.chunk_id for r in revisions}
    if chunks is not None:
        wrote &= set(chunks)
    return [
        (chunk, link(head_of(chunk) or GENESIS, chunk, record, revisions))
        for chunk in sorted(wrote)
    ]


def rebuild(
    chunk: ChunkId,
    records: Mapping[CommitId, CommitRecord],
    revisions: Iterable[Revision],
    base: Sequence[tuple[CommitId, bytes]] = (),
) -> list[tuple[CommitId, bytes]]:
    """A chunk's whole chain from its stored history: (commit, link) of every
    commit that wrote to it, in commit order (time, then id).

    `base` is the chain's compacted part (`mapctl gc`): the links of the commits
    some of whose revisions were dropped, which the history can no longer give.
    They are kept as they are, and the chain goes on from the last of them over
    the commits after it, which the history holds whole.

    Commit times grow strictly along a chunk's history on every commit path (a
    writer stamps past every holder's clock, a chunk's log past the chunk's
    clock), so this is the order the holders applied them in, and a replica
    rebuilt here has the chain its holders built commit by commit.

    Raises:
        KeyError: a revision's commit is not in `records`.
    """
    compacted = {commit for commit, _ in base}
    by_commit: dict[CommitId, list[Revision]] = {}
    for revision in revisions:
        if revision.chunk_id == chunk and revision.commit_id not in compacted:
            by_commit.setdefault(revision.commit_id, []).append(revision)
    ordered = sorted(by_commit, key=lambda c: (records[c].time, c))
    start = base[-1][1] if base else GENESIS
    links = replay(chunk, [(records[c], by_commit[c]) for c in ordered], start)
    return [*base, *zip(ordered, links, strict=True)]


def _text(h: hashlib._Hash, text: str) -> None:
    data = text.encode("utf-8")
    h.update(struct.pack(">I", len(data)))  # length first: "ab"+"c" and "a"+"bc" differ
    h.update(data)
