"""Snapshot isolation of `Peer` against a brute-force model (DESIGN §4-5).

The model keeps, per item, every (commit time, value or None for removed).
A transaction must read the model as it was at its begin time, overlaid with
its own earlier commits and its buffered writes; a commit must succeed iff no
item of its write set (and, under serializable isolation, of its read set)
changed after the transaction's begin time (or after its own last commit of
the item), and then lands in the model at the commit time.
"""

from __future__ import annotations

import asyncio
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import hypothesis.strategies as st
from google.protobuf.wrappers_pb2 import Int64Value
from hypothesis import event, settings
from hypothesis.stateful import (
    RuleBasedStateMachine,
    initialize,
    invariant,
    precondition,
    rule,
)

from mapapi import ChunkId, ConflictError, ItemId, Peer, Transaction
from mapapi.core.transaction import Isolation
from mapapi.store.sqlite import SqliteStore

TABLE = "values"
ITEMS = [ItemId(f"{i:032x}") for i in range(1, 6)]
VALUES = st.integers(min_value=-1000, max_value=1000)
WRITES = st.dictionaries(st.sampled_from(ITEMS), st.none() | VALUES, min_size=1, max_size=3)
MAX_OPEN = 4

History = list[tuple[int, int | None]]


def value_at(history: History, time: int) -> int | None:
    """The model's value of an item at `time` (None: absent or removed)."""
    found = None
    for when, value in history:
        if when > time:
            break
        found = value
    return found


@dataclass
class TxModel:
    """What the model knows about one open transaction."""

    tx: Transaction
    begin: int
    isolation: Isolation
    buffer: dict[ItemId, tuple[str, int | None]] = field(default_factory=dict)
    own: dict[ItemId, tuple[int, int | None]] = field(default_factory=dict)
    read: set[ItemId] = field(default_factory=set)
    scanned: bool = False

    def since(self, item: ItemId) -> int:
        own = self.own.get(item)
        return own[0] if own is not None else self.begin


class SnapshotMachine(RuleBasedStateMachine):
    """Several interleaved transactions on one peer versus the model."""

    def __init__(self) -> None:
        super().__init__()
        self.model: dict[ItemId, History] = {item: [] for item in ITEMS}
        self.now = 0
        self.commits = 0
        self.txs: dict[int, TxModel] = {}
        self.next_tx = 0
        self.chunks: list[ChunkId] = []
        self.peer = self.make_peer()

    def make_peer(self) -> Peer:
        raise NotImplementedError

    def cleanup(self) -> None:
        """Release what `make_peer` created."""

    def teardown(self) -> None:
        asyncio.run(self.peer.close())
        self.cleanup()

    @initialize()
    def create_schema(self) -> None:
        asyncio.run(self.peer.create_table(TABLE, Int64Value))
        self.chunks = [asyncio.run(self.peer.create_chunk(TABLE)) for _ in range(2)]
        # Start from a few committed items, so early steps have something to conflict on.
        tx = self.peer.begin()
        for index, item in enumerate(ITEMS[:3]):
            tx.insert(TABLE, Int64Value(value=index), self.chunks[index % 2], item)
        record = asyncio.run(tx.commit("seed"))
        assert record is not None
        self.now = record.time
        self.commits = 1
        for index, item in enumerate(ITEMS[:3]):
            self.model[item].append((record.time, index))

    # -- helpers ---------------------------------------------------------------
    def latest_time(self, item: ItemId) -> int:
        history = self.model[item]
        return history[-1][0] if history else 0

    def seen(self, t: TxModel, item: ItemId) -> int | None:
        """What transaction `t` must read for `item`."""
        if item in t.buffer:
            return t.buffer[item][1]
        if item in t.own:
            return t.own[item][1]
        return value_at(self.model[item], t.begin)

    def expected_conflicts(self, t: TxModel) -> set[ItemId]:
        checked = set(t.buffer)
        if t.isolation == "serializable":
            checked |= set(ITEMS) if t.scanned else t.read
        return {
            item for item in checked if self.model[item] and self.latest_time(item) > t.since(item)
        }

    def pick(self, data: st.DataObject) -> tuple[int, TxModel]:
        """One open transaction (begun now if none is open, so every rule can run)."""
        if not self.txs:
            self.add_tx(self.peer.begin(), "snapshot")
        key = data.draw(st.sampled_from(sorted(self.txs)), label="tx")
        return key, self.txs[key]

    def add_tx(self, tx: Transaction, isolation: Isolation) -> TxModel:
        t = TxModel(tx, tx.begin_time, isolation)
        self.txs[self.next_tx] = t
        self.next_tx += 1
        return t

    # -- rules -------------------------------------------------------------------
    @precondition(lambda self: len(self.txs) < MAX_OPEN)
    @rule(data=st.data(), serializable=st.booleans(), past=st.booleans())
    def begin(self, data: st.DataObject, serializable: bool, past: bool) -> None:
        """Begin now, or at a past logical time."""
        isolation: Isolation = "serializable" if serializable else "snapshot"
        at = data.draw(st.integers(min_value=0, max_value=self.now), label="at") if past else None
        tx = self.peer.begin(at, isolation=isolation)
        assert tx.begin_time == (self.now if at is None else at)
        self.add_tx(tx, isolation)

    @rule(data=st.data(), item=st.sampled_from(ITEMS))
    def read(self, data: st.DataObject, item: ItemId) -> None:
        _, t = self.pick(data)
        message: Any = asyncio.run(t.tx.get(TABLE, item))
        t.read.add(item)
        assert (None if message is None else message.value) == self.seen(t, item)

    @rule(data=st.data())
    def scan(self, data: st.DataObject) -> None:
        _, t = self.pick(data)
        found: dict[ItemId, Any] = asyncio.run(t.tx.items(TABLE))
        t.scanned = True
        expected = {i: v for i in ITEMS if (v := self.seen(t, i)) is not None}
        assert {i: m.value for i, m in found.items()} == expected

    @rule(data=st.data(), writes=WRITES)
    def write(self, data: st.DataObject, writes: dict[ItemId, int | None]) -> None:
        """Per item: remove (None), else insert if the transaction sees it absent or update."""
        _, t = self.pick(data)
        for item, value in writes.items():
            if value is None:
                self.remove_one(t, item)
            else:
                self.write_one(data, t, item, value)

    def write_one(self, data: st.DataObject, t: TxModel, item: ItemId, value: int) -> None:
        previous = t.buffer.get(item)
        if self.seen(t, item) is None:
            if previous is not None:
                return  # a buffered removal: neither insert nor update applies
            chunk = data.draw(st.sampled_from(self.chunks), label="chunk")
            t.tx.insert(TABLE, Int64Value(value=value), chunk, item)
            t.buffer[item] = ("insert", value)
        else:
            t.tx.update(TABLE, item, Int64Value(value=value))
            op = "insert" if previous is not None and previous[0] == "insert" else "update"
            t.buffer[item] = (op, value)

    def remove_one(self, t: TxModel, item: ItemId) -> None:
        if self.seen(t, item) is None:
            return
        t.tx.remove(TABLE, item)
        previous = t.buffer.get(item)
        if previous is not None and previous[0] == "insert":
            del t.buffer[item]  # inserted then removed: nothing to write
        else:
            t.buffer[item] = ("remove", None)

    @rule(data=st.data())
    def commit(self, data: st.DataObject) -> None:
        key, t = self.pick(data)
        expected = self.expected_conflicts(t)
        try:
            record = asyncio.run(t.tx.commit())
        except ConflictError as err:
            self.check_conflict(key, t, expected, err, data)
            return
        assert not expected, f"commit accepted despite conflicts on {expected}"
        if not t.buffer:
            assert record is None
            return
        assert record is not None
        assert record.time > self.now
        self.now = record.time
        self.commits += 1
        event("commit applied")
        for item, (_, value) in t.buffer.items():
            self.model[item].append((record.time, value))
            t.own[item] = (record.time, value)
        t.buffer.clear()

    def check_conflict(
        self, key: int, t: TxModel, expected: set[ItemId], err: ConflictError, data: st.DataObject
    ) -> None:
        """The refusal must name exactly the model's conflicts; maybe continue with merge()."""
        assert expected, f"commit refused but nothing changed: {err.conflicts}"
        assert {c.item_id for c in err.conflicts} == expected
        assert err.seen_at == self.now
        for c in err.conflicts:  # base (at our begin), ours, theirs (the newest revision)
            base = None if c.base is None else Int64Value.FromString(c.base.data).value
            assert base == value_at(self.model[c.item_id], t.begin)
            assert (c.ours is None) == (c.item_id not in t.buffer)
            assert c.theirs.update_time == self.latest_time(c.item_id)
        del self.txs[key]
        event("commit refused")
        if data.draw(st.booleans(), label="merge"):
            merged = self.add_tx(err.merge(), t.isolation)
            merged.buffer = {i: c for i, c in t.buffer.items() if i not in expected}

    @precondition(lambda self: len(self.txs) >= MAX_OPEN - 1)
    @rule(data=st.data())
    def abort(self, data: st.DataObject) -> None:
        key, t = self.pick(data)
        t.tx.abort()
        del self.txs[key]

    # -- invariants ----------------------------------------------------------------
    @invariant()
    def store_matches_model(self) -> None:
        assert self.peer.now() == self.now
        assert len(self.peer.log()) == self.commits
        for item in ITEMS:
            stored = [
                (r.update_time, None if r.removed else Int64Value.FromString(r.data).value)
                for r in self.peer.history(item)
            ]
            assert stored == self.model[item], item


class MemorySnapshotMachine(SnapshotMachine):
    def make_peer(self) -> Peer:
        return Peer.in_memory()


class SqliteSnapshotMachine(SnapshotMachine):
    def make_peer(self) -> Peer:
        self.folder = Path(tempfile.mkdtemp(prefix="mapapi-si-"))
        return Peer(SqliteStore(self.folder / "store.sqlite", create=True))

    def cleanup(self) -> None:
        shutil.rmtree(self.folder, ignore_errors=True)


_SETTINGS = settings(max_examples=200, stateful_step_count=50)
TestMemorySnapshotIsolation = MemorySnapshotMachine.TestCase
TestMemorySnapshotIsolation.settings = _SETTINGS
TestSqliteSnapshotIsolation = SqliteSnapshotMachine.TestCase
TestSqliteSnapshotIsolation.settings = settings(max_examples=100, stateful_step_count=50)
