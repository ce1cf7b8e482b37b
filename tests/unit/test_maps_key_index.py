"""The mission rules' key index answers what the rows held here say (mapapi.maps.rules).

The index is kept lean (a key's items, an item's keys in one flat tuple, shared
mission names), so its answers are checked against the store itself: after any
sequence of inserts, updates, removals and dropped chunks, each key's items,
each item's keys and each mission's count of keys are what the newest held rows
give, for vertices (one key each) and edges (two, possibly the same one).
"""

from __future__ import annotations

import tempfile
from collections import Counter
from pathlib import Path

from hypothesis import given, settings
from hypothesis import strategies as st

from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId
from mapapi.maps.rules import KeyIndex, edge_keys, vertex_keys
from mapapi.maps.schema import Edge, Vertex
from mapapi.store import SqliteStore

AUTHOR = PeerId.new()
MISSIONS = ("a", "b")

key_st = st.tuples(st.sampled_from(MISSIONS), st.integers(0, 5))
# one step: (chunk 0-2, item slot 0-7, new keys or None for a removal), or a dropped chunk
step_st = st.one_of(
    st.tuples(
        st.integers(0, 2), st.integers(0, 7), st.none() | st.lists(key_st, min_size=1, max_size=2)
    ),
    st.tuples(st.just(-1), st.integers(0, 2), st.none()),
)


def _payload(keys: list[tuple[str, int]]) -> bytes:
    if len(keys) == 1:
        return Vertex(mission=keys[0][0], index=keys[0][1]).SerializeToString()
    edge = Edge(mission=keys[0][0])
    edge.from_vertex.mission, edge.from_vertex.index = keys[0]
    edge.to_vertex.mission, edge.to_vertex.index = keys[1]
    return edge.SerializeToString()


def _keys_of(data: bytes) -> tuple[tuple[str, int], ...]:
    """A vertex's key or an edge's two (the test's rows are of both kinds)."""
    if not data:
        return ()
    edge = Edge.FromString(data)
    return edge_keys(data) if edge.HasField("to_vertex") else vertex_keys(data)


@settings(max_examples=60, deadline=None)
@given(steps=st.lists(step_st, max_size=40), catch_every=st.integers(1, 5))
def test_the_index_answers_what_the_held_rows_say(
    steps: list[tuple[int, int, list[tuple[str, int]] | None]], catch_every: int
) -> None:
    with tempfile.TemporaryDirectory() as scratch:
        store = SqliteStore(Path(scratch) / "store.sqlite", create=True)
        try:
            _check(store, steps, catch_every)
        finally:
            store.close()


def _check(
    store: SqliteStore,
    steps: list[tuple[int, int, list[tuple[str, int]] | None]],
    catch_every: int,
) -> None:
    store.add_table("rows", "mapapi.v1.Edge")
    chunks = [ChunkId.new() for _ in range(3)]
    for chunk in chunks:
        store.add_chunk(chunk, "rows")
    slots = [ItemId.new() for _ in range(24)]  # 8 per chunk: an item stays in its chunk
    index = KeyIndex("rows", _keys_of)
    for time, (chunk_no, slot, keys) in enumerate(steps, start=1):
        if chunk_no == -1:
            if chunks[slot] in store.chunk_ids():
                store.drop_chunk(chunks[slot])
        elif chunks[chunk_no] in store.chunk_ids():
            item, chunk = slots[chunk_no * 8 + slot], chunks[chunk_no]
            record = CommitRecord(CommitId.new(), time, AUTHOR, "", (chunk,))
            data = b"" if keys is None else _payload(keys)
            revision = Revision(
                item, "rows", chunk, data, time, time, keys is None, AUTHOR, record.id
            )
            store.apply_commit(record, [revision])
        if time % catch_every == 0:
            index.catch_up(store)
    index.catch_up(store)

    held = {
        r.item_id: _keys_of(r.data)
        for chunk in store.chunk_ids()
        for r in store.scan(store.clock(), chunk=chunk)
    }
    for item in slots:
        assert index.keys(item) == held.get(item, ())
    every_key = {(m, i) for m in MISSIONS for i in range(6)}
    for key in every_key:
        want = sorted(i for i, keys in held.items() for _ in range(keys.count(key)))
        assert sorted(index.holders(key)) == want
    rows = Counter(m for keys in held.values() for m, _ in keys)
    for mission in MISSIONS:
        assert index.rows(mission) == rows[mission]
