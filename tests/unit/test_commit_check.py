"""What a chunk's leader refuses to append (mapapi.swarm.commit_check, DESIGN §11, §13).

A real proposal passes; each way a hostile or broken writer could make one break
every replica (another author, an item of another chunk, a wrong table, a payload
of another type or over the limit, ...) is refused with a UsageError naming it,
before the proposal enters the chunk's log; so is an entry whose time would push
the chunk's clock more than `limits.MAX_CLOCK_JUMP` ahead of the leader's.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from mapapi._pb.mapapi.v1.types_pb2 import Counter
from mapapi.core import codec, limits
from mapapi.core.change import Change, Op
from mapapi.core.errors import ChunkNotFound, LimitExceeded, NotParticipatingError, UsageError
from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId
from mapapi.core.proposal import LogEntry, Proposal, TimeFloor, TxDecision
from mapapi.store.base import TxRow
from mapapi.store.sqlite import SqliteStore
from mapapi.swarm.commit_check import check_proposal

WRITER, STRANGER = PeerId.new(), PeerId.new()
MEMBERS = {WRITER, PeerId.new()}  # the group of chunk a
TABLE = "counters"
ONE = Counter(value=1).SerializeToString()
NOW = 10  # the leader's Lamport clock


class World:
    """A store with chunks a and b of counters (item `other` is in b) and c of another table."""

    def __init__(self, store: SqliteStore) -> None:
        self.store = store
        store.add_table(TABLE, "mapapi.v1.Counter")
        store.add_table("other", "google.protobuf.Struct")
        self.a, self.b, self.c = ChunkId.new(), ChunkId.new(), ChunkId.new()
        store.add_chunk(self.a, TABLE)
        store.add_chunk(self.b, TABLE)
        store.add_chunk(self.c, "other")
        self.old, self.other = ItemId.new(), ItemId.new()
        for item, chunk in ((self.old, self.a), (self.other, self.b)):
            record = CommitRecord(CommitId.new(), 5, WRITER, "", (chunk,))
            revision = Revision(item, TABLE, chunk, ONE, 5, 5, False, WRITER, record.id)
            store.apply_commit(record, [revision])

    def proposal(self, *changes: Change, author: PeerId = WRITER) -> Proposal:
        """A proposal to chunk a: by default an update of `old` and an insert."""
        changes = changes or (
            Change(Op.UPDATE, TABLE, self.old, self.a, Counter(value=2).SerializeToString()),
            Change(Op.INSERT, TABLE, ItemId.new(), self.a, ONE),
        )
        return Proposal(CommitId.new(), 9, author, "w", "", "m", 5, "snapshot", changes)


@pytest.fixture
def world(tmp_path: Path) -> Iterator[World]:
    store = SqliteStore(tmp_path / "store.sqlite", create=True)
    yield World(store)
    store.close()


def test_a_real_proposal_decisions_and_floors_pass(world: World) -> None:
    check_proposal(world.store, world.a, world.proposal(), WRITER, MEMBERS, NOW)
    check_proposal(world.store, world.a, TxDecision(CommitId.new(), False), PeerId.new(), (), NOW)
    check_proposal(world.store, world.a, TimeFloor(7), WRITER, MEMBERS, NOW)


def test_a_proposal_in_someone_elses_name_is_refused(world: World) -> None:
    with pytest.raises(UsageError, match="proposes its own commits only"):
        check_proposal(world.store, world.a, world.proposal(), STRANGER, {*MEMBERS, STRANGER}, NOW)


@pytest.mark.parametrize(
    ("change", "complaint"),
    [
        (lambda w: Change(Op.INSERT, TABLE, ItemId.new(), w.b, ONE), "not filed under chunk"),
        (lambda w: Change(Op.INSERT, "other", ItemId.new(), w.a, ONE), "not filed under chunk"),
        (lambda w: Change(Op.UPDATE, TABLE, w.other, w.a, ONE), "belongs to chunk"),
        (lambda w: Change(Op.REMOVE, TABLE, w.old, w.a, ONE), "carries a payload"),
        (lambda w: Change(Op.UPDATE, TABLE, w.old, w.a, b"\xff\xff"), "Counter"),
    ],
)
def test_a_write_that_would_break_the_store_is_refused(
    world: World, change: object, complaint: str
) -> None:
    bad = change(world)  # type: ignore[operator]
    with pytest.raises(UsageError, match=complaint):
        check_proposal(world.store, world.a, world.proposal(bad), WRITER, MEMBERS, NOW)


def test_one_item_twice_is_refused(world: World) -> None:
    twice = Change(Op.UPDATE, TABLE, world.old, world.a, ONE)
    with pytest.raises(UsageError, match="changed twice"):
        check_proposal(
            world.store,
            world.a,
            world.proposal(twice, dataclasses.replace(twice)),
            WRITER,
            MEMBERS,
            NOW,
        )


def test_a_payload_over_its_limit_and_an_unknown_chunk_are_refused(
    world: World, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(limits, "MAX_PAYLOAD_BYTES", 10)
    big = Change(
        Op.INSERT, TABLE, ItemId.new(), world.a, Counter(name="x" * 20).SerializeToString()
    )
    with pytest.raises(LimitExceeded):
        check_proposal(world.store, world.a, world.proposal(big), WRITER, MEMBERS, NOW)
    with pytest.raises(ChunkNotFound):
        check_proposal(world.store, ChunkId.new(), world.proposal(), WRITER, MEMBERS, NOW)


def test_a_peer_that_is_no_member_proposes_nothing(world: World) -> None:
    for entry in (world.proposal(author=STRANGER), TimeFloor(7)):
        with pytest.raises(NotParticipatingError, match="no member"):
            check_proposal(world.store, world.a, entry, STRANGER, MEMBERS, NOW)


def test_only_the_coordinator_decides_commit(world: World) -> None:
    prepare = dataclasses.replace(world.proposal(), participants=(world.a, world.b))
    world.store.raft_save(world.a, hard=(1, 0, 0))
    row = TxRow("prepared", 9, codec.encode_entry(prepare))
    world.store.raft_tx_put(world.a, prepare.commit_id, row)
    commit = TxDecision(prepare.commit_id, True, 9)
    with pytest.raises(UsageError, match="only a coordinator decides commit"):
        check_proposal(world.store, world.a, commit, STRANGER, MEMBERS, NOW)
    check_proposal(world.store, world.a, commit, WRITER, MEMBERS, NOW)
    check_proposal(world.store, world.a, TxDecision(prepare.commit_id, False), STRANGER, (), NOW)


def test_a_proposal_under_an_existing_commit_id_is_refused(world: World) -> None:
    (old,) = [c for c in world.store.commits() if world.a in c.chunks]
    replayed = dataclasses.replace(world.proposal(), commit_id=old.id)
    with pytest.raises(UsageError, match="exists already"):
        check_proposal(world.store, world.a, replayed, WRITER, MEMBERS, NOW)


MakeEntry = Callable[[World, int], LogEntry]
"""An entry to chunk a at a given time."""


@pytest.mark.parametrize(
    "make",
    [
        lambda w, t: dataclasses.replace(w.proposal(), time=t),
        lambda w, t: dataclasses.replace(w.proposal(), begin_time=t),
        lambda w, t: TxDecision(CommitId.new(), True, t),
        lambda w, t: TimeFloor(t),
    ],
    ids=["time", "begin_time", "decision", "floor"],
)
def test_an_entry_far_ahead_of_the_leaders_clock_is_refused(world: World, make: MakeEntry) -> None:
    """One entry at MAX_LAMPORT would make every later commit of the chunk
    unacceptable to every peer (its time MAX_LAMPORT + 1): the wire fuzzer found it."""
    within = make(world, NOW + limits.MAX_CLOCK_JUMP)
    check_proposal(world.store, world.a, within, WRITER, MEMBERS, NOW)
    for far in (NOW + limits.MAX_CLOCK_JUMP + 1, limits.MAX_LAMPORT):
        with pytest.raises(LimitExceeded, match="MAX_CLOCK_JUMP"):
            check_proposal(world.store, world.a, make(world, far), WRITER, MEMBERS, NOW)
