"""A chunk's state serialized in parts and read back part by part (core/pb_parts.py):
the same bytes as the message serialized whole, the same state back, and damaged
bytes refused, whatever the rows and however small the parts."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mapapi._pb.mapapi.v1 import core_pb2
from mapapi.core import codec, pb_parts
from mapapi.core.chunk_state import ChunkState, TxState
from mapapi.core.errors import CorruptRepoError
from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId

CHUNK = ChunkId.new()
AUTHOR = PeerId.new()


def revision(n: int, data: bytes) -> Revision:
    removed = n % 5 == 0
    return Revision(
        ItemId.new(),
        "t",
        CHUNK,
        b"" if removed else data,
        n,
        n + 1,
        removed,
        AUTHOR,
        CommitId.new(),
    )


def record(n: int) -> CommitRecord:
    return CommitRecord(CommitId.new(), n + 1, AUTHOR, f"commit {n}", (CHUNK,), f"robot-{n}")


states = st.builds(
    lambda revs, commits, txs, time: ChunkState(
        "t",
        "google.protobuf.Struct",
        time,
        tuple(revision(i, d) for i, d in enumerate(revs)),
        tuple(record(i) for i in range(commits)),
        tuple(TxState(CommitId.new(), "prepared", i + 1, d) for i, d in enumerate(txs)),
    ),
    st.lists(st.binary(max_size=300), max_size=60),
    st.integers(0, 30),
    st.lists(st.binary(max_size=50), max_size=3),
    st.integers(0, 2**62),
)


def whole(state: ChunkState) -> bytes:
    """The state serialized as one message, as the runtime does it in one call."""
    m = core_pb2.ChunkSnapshot(table=state.table, type_name=state.type_name, time=state.time)
    m.revisions.extend(codec.revision_to_pb(r) for r in state.revisions)
    m.commits.extend(codec.commit_record_to_pb(c) for c in state.commits)
    for tx in state.txs:
        m.txs.add(commit_id=tx.commit_id.to_bytes(), state=tx.state, time=tx.time, data=tx.data)
    return bytes(m.SerializeToString())


@settings(max_examples=60, deadline=None)
@given(states, st.integers(1, 7), st.integers(1, 4000))
def test_parts_are_the_message_serialized_whole(
    state: ChunkState, per_part: int, size: int
) -> None:
    """Encoded in parts of `per_part` rows: the bytes of the whole message; cut
    into parts of about `size` bytes and merged back: the same state."""
    old = codec.PART_ITEMS
    codec.PART_ITEMS = per_part
    try:
        data = codec.encode_chunk_state(state)
    finally:
        codec.PART_ITEMS = old
    assert data == whole(state)
    cut = list(pb_parts.parts(data, size))
    assert b"".join(cut) == data
    assert all(len(p) < size + 400 for p in cut[:-1])  # a part ends at the first field past size
    assert codec.decode_chunk_state(data) == state


@settings(max_examples=60, deadline=None)
@given(states, st.data())
def test_a_truncated_state_is_refused(state: ChunkState, data: st.DataObject) -> None:
    """Bytes cut inside a field are a damaged snapshot, never a smaller state."""
    encoded = codec.encode_chunk_state(state)
    if len(encoded) < 2:
        return
    end = data.draw(st.integers(1, len(encoded) - 1))
    try:
        got = codec.decode_chunk_state(encoded[:end])
    except CorruptRepoError:
        return
    assert got != state  # a cut on a field boundary: a well-formed, smaller message


def test_a_field_of_an_unknown_wire_type_is_refused() -> None:
    with pytest.raises(ValueError, match="wire type 7"):
        list(pb_parts.parts(bytes([0x0F, 0x01])))
    with pytest.raises(ValueError, match="past the end"):
        list(pb_parts.parts(bytes([0x22, 0x05, 0x01])))
