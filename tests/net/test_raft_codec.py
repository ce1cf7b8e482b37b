"""Raft batches on the wire (net/raft_codec.py): the direct converter writes the
bytes the generic one writes, reads back the same batch, and checks the same limits."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from mapapi._pb.mapapi.v1 import wire_pb2
from mapapi.core import limits
from mapapi.core.errors import LimitExceeded
from mapapi.core.ids import ChunkId
from mapapi.net import fields, raft_codec
from mapapi.net.messages import RaftBatch, RaftEntry, RaftMessage

u64 = st.integers(min_value=0, max_value=2**63)
entries = st.builds(RaftEntry, u64, u64, st.integers(0, 5), st.binary(max_size=64))
messages = st.builds(
    RaftMessage,
    st.builds(lambda: ChunkId.new()),
    st.integers(0, 20),
    u64,
    u64,
    u64,
    u64,
    u64,
    st.tuples(entries, entries) | st.just(()),
    u64,
    st.booleans(),
    u64,
    st.booleans(),
    u64,
    u64,
    st.binary(max_size=32),
    st.binary(max_size=64),
    st.binary(max_size=24),
)


@given(st.lists(messages, max_size=5).map(lambda ms: RaftBatch(tuple(ms))))
def test_the_direct_converter_writes_and_reads_what_the_generic_one_does(batch: RaftBatch) -> None:
    generic, direct = wire_pb2.RaftBatch(), wire_pb2.RaftBatch()
    fields.fill(batch, generic)
    raft_codec.fill_batch(batch, direct)
    assert direct.SerializeToString(deterministic=True) == generic.SerializeToString(
        deterministic=True
    )
    assert raft_codec.read_batch(direct) == batch == fields.read(RaftBatch, generic)


def test_a_batch_over_a_limit_is_refused(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(limits.MAX_COUNT, "entries", 2)
    entry = RaftEntry(1, 1, 1, b"x")
    message = RaftMessage(
        ChunkId.new(), 1, 1, 2, 1, 0, 0, (entry,) * 3, 0, False, 0, False, 0, 0, b"", b"", b""
    )
    m = wire_pb2.RaftBatch()
    raft_codec.fill_batch(RaftBatch((message,)), m)
    with pytest.raises(LimitExceeded, match="entries"):
        raft_codec.read_batch(m)
