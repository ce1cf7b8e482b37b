"""A chunk's commits form a hash chain (core/chain.py)."""

from __future__ import annotations

from dataclasses import replace

from hypothesis import given
from hypothesis import strategies as st

from mapapi.core.chain import GENESIS, link, replay
from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId

CHUNK = ChunkId.new()
AUTHOR = PeerId.new()


def commit(time: int, data: bytes, chunk: ChunkId = CHUNK) -> tuple[CommitRecord, list[Revision]]:
    record = CommitRecord(CommitId.new(), time, AUTHOR, f"c{time}", (chunk,))
    revision = Revision(ItemId.new(), "t", chunk, data, time, time, False, AUTHOR, record.id)
    return record, [revision]


HISTORY = [commit(t, f"v{t}".encode()) for t in range(1, 6)]


def test_the_same_history_gives_the_same_head() -> None:
    assert replay(CHUNK, HISTORY) == replay(CHUNK, list(HISTORY))
    assert replay(CHUNK, HISTORY)[0] == link(GENESIS, CHUNK, *HISTORY[0])


def test_a_flipped_byte_changes_its_link_and_every_later_one() -> None:
    record, revisions = HISTORY[2]
    damaged = [replace(revisions[0], data=b"v3" + b"\x01")]
    links = replay(CHUNK, HISTORY)
    other = replay(CHUNK, [*HISTORY[:2], (record, damaged), *HISTORY[3:]])
    assert other[:2] == links[:2]
    assert all(a != b for a, b in zip(other[2:], links[2:], strict=True))


def test_a_dropped_commit_changes_the_head() -> None:
    assert replay(CHUNK, HISTORY)[-1] != replay(CHUNK, HISTORY[:2] + HISTORY[3:])[-1]


def test_revisions_of_other_chunks_do_not_count() -> None:
    record, revisions = HISTORY[0]
    elsewhere = commit(1, b"x", ChunkId.new())[1]
    assert link(GENESIS, CHUNK, record, revisions) == link(
        GENESIS, CHUNK, record, [*revisions, *elsewhere]
    )


@given(st.text(max_size=5), st.text(max_size=5))
def test_messages_are_framed(left: str, right: str) -> None:
    """Two different messages never hash alike through concatenation."""
    record = HISTORY[0][0]
    one = link(GENESIS, CHUNK, replace(record, message=left + right), [])
    two = link(GENESIS, CHUNK, replace(record, message=left + "|" + right), [])
    assert one != two
