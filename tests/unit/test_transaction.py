"""Transactions (mapapi.core.transaction, DESIGN §5).

The pure part (`validate`, `build_revisions`) is tested on hand-made revisions;
the behaviour of a `Transaction` runs on a real peer, once on a `MemoryStore`
and once on a SQLite repository, since both must behave alike.
"""

from collections.abc import Awaitable, Callable
from dataclasses import dataclass

import pytest
from google.protobuf.message import Message

from mapapi import (
    ChunkId,
    CommitRecord,
    ConflictError,
    ItemId,
    ItemNotFound,
    Peer,
    UsageError,
    ViewClosedError,
)
from mapapi.core.change import Change, Op
from mapapi.core.history import Revision
from mapapi.core.ids import CommitId, PeerId
from mapapi.core.transaction import Transaction, TxState
from mapapi.core.validate import build_revisions, validate

# -- pure validation ----------------------------------------------------------

CHUNK = ChunkId.new()
THEM = PeerId.new()
BEGIN = 10


def rev(
    item: ItemId, time: int, data: bytes = b"theirs", *, removed: bool = False, inserted: int = 1
) -> Revision:
    return Revision(
        item, "t", CHUNK, b"" if removed else data, inserted, time, removed, THEM, CommitId.new()
    )


def change(op: Op, item: ItemId, data: bytes = b"ours") -> Change:
    return Change(op, "t", item, CHUNK, b"" if op is Op.REMOVE else data)


def at_begin(_: ItemId) -> int:
    return BEGIN


class TestValidate:
    def test_untouched_items_are_accepted_in_order(self) -> None:
        a, b, c = ItemId.new(), ItemId.new(), ItemId.new()
        changes = [change(Op.UPDATE, a), change(Op.REMOVE, b), change(Op.INSERT, c)]
        latest = {a: rev(a, BEGIN), b: rev(b, BEGIN - 3)}
        accepted, conflicts = validate(changes, latest, at_begin)
        assert accepted == changes
        assert conflicts == []

    @pytest.mark.parametrize("op", [Op.UPDATE, Op.REMOVE])
    def test_foreign_write_after_begin_conflicts(self, op: Op) -> None:
        item = ItemId.new()
        base, theirs = rev(item, BEGIN - 1, b"base"), rev(item, BEGIN + 1)
        ours = change(op, item)
        accepted, conflicts = validate(
            [ours], {item: theirs}, at_begin, base_of=lambda i: base if i == item else None
        )
        assert accepted == []
        assert len(conflicts) == 1
        conflict = conflicts[0]
        assert (conflict.item_id, conflict.table, conflict.chunk_id) == (item, "t", CHUNK)
        assert conflict.base is base
        assert conflict.ours is ours
        assert conflict.theirs is theirs

    def test_update_of_an_item_removed_after_begin_conflicts(self) -> None:
        item = ItemId.new()
        tombstone = rev(item, BEGIN + 2, removed=True)
        calls: list[ItemId] = []

        def merge(ours: Change, theirs: Revision, base: Revision | None) -> bytes | None:
            calls.append(ours.item_id)
            return b"merged"

        accepted, conflicts = validate(
            [change(Op.UPDATE, item)], {item: tombstone}, at_begin, try_merge=merge
        )
        assert accepted == []
        assert [c.theirs for c in conflicts] == [tombstone]
        assert calls == []  # nothing to merge with a tombstone

    def test_insert_conflicts_when_the_id_exists(self) -> None:
        item = ItemId.new()
        existing = rev(item, BEGIN - 5)
        accepted, conflicts = validate([change(Op.INSERT, item)], {item: existing}, at_begin)
        assert accepted == []
        assert [c.theirs for c in conflicts] == [existing]

    def test_reinsert_over_a_tombstone_seen_at_begin_is_accepted(self) -> None:
        item = ItemId.new()
        ours = change(Op.INSERT, item)
        accepted, conflicts = validate([ours], {item: rev(item, BEGIN, removed=True)}, at_begin)
        assert accepted == [ours]
        assert conflicts == []

    def test_reinsert_over_a_later_tombstone_conflicts(self) -> None:
        item = ItemId.new()
        tombstone = rev(item, BEGIN + 1, removed=True)
        accepted, conflicts = validate([change(Op.INSERT, item)], {item: tombstone}, at_begin)
        assert accepted == []
        assert [c.theirs for c in conflicts] == [tombstone]

    def test_since_is_per_item(self) -> None:
        mine, other = ItemId.new(), ItemId.new()
        own_commit = BEGIN + 4
        latest = {mine: rev(mine, own_commit), other: rev(other, own_commit)}
        accepted, conflicts = validate(
            [change(Op.UPDATE, mine), change(Op.UPDATE, other)],
            latest,
            lambda i: own_commit if i == mine else BEGIN,
        )
        assert [c.item_id for c in accepted] == [mine]
        assert [c.item_id for c in conflicts] == [other]

    def test_base_that_was_a_tombstone_is_reported_as_absent(self) -> None:
        item = ItemId.new()
        accepted, conflicts = validate(
            [change(Op.UPDATE, item)],
            {item: rev(item, BEGIN + 1)},
            at_begin,
            base_of=lambda _: rev(item, BEGIN - 1, removed=True),
        )
        assert accepted == []
        assert conflicts[0].base is None

    def test_merge_policy_result_replaces_our_payload(self) -> None:
        item = ItemId.new()
        base, theirs = rev(item, BEGIN - 1, b"base"), rev(item, BEGIN + 1)
        seen: list[tuple[bytes, bytes, bytes | None]] = []

        def merge(ours: Change, theirs: Revision, base: Revision | None) -> bytes | None:
            seen.append((ours.data, theirs.data, None if base is None else base.data))
            return b"merged"

        ours = change(Op.UPDATE, item)
        accepted, conflicts = validate(
            [ours], {item: theirs}, at_begin, try_merge=merge, base_of=lambda _: base
        )
        assert conflicts == []
        assert accepted == [Change(Op.UPDATE, "t", item, CHUNK, b"merged")]
        assert seen == [(b"ours", b"theirs", b"base")]

    def test_merge_policy_declining_leaves_the_conflict(self) -> None:
        item = ItemId.new()
        accepted, conflicts = validate(
            [change(Op.UPDATE, item)],
            {item: rev(item, BEGIN + 1)},
            at_begin,
            try_merge=lambda *_: None,
        )
        assert accepted == []
        assert len(conflicts) == 1

    @pytest.mark.parametrize("op", [Op.INSERT, Op.REMOVE])
    def test_merge_policy_only_sees_update_update(self, op: Op) -> None:
        item = ItemId.new()
        accepted, conflicts = validate(
            [change(op, item)],
            {item: rev(item, BEGIN + 1)},
            at_begin,
            try_merge=lambda *_: b"merged",
        )
        assert accepted == []
        assert len(conflicts) == 1

    def test_read_set_written_by_others_conflicts_without_ours(self) -> None:
        read, quiet, gone = ItemId.new(), ItemId.new(), ItemId.new()
        theirs = rev(read, BEGIN + 1)
        accepted, conflicts = validate(
            [],
            {read: theirs, quiet: rev(quiet, BEGIN)},
            at_begin,
            read_set=[read, quiet, gone],
        )
        assert accepted == []
        assert [(c.item_id, c.ours, c.theirs) for c in conflicts] == [(read, None, theirs)]

    def test_read_and_written_item_is_reported_once(self) -> None:
        item = ItemId.new()
        _, conflicts = validate(
            [change(Op.UPDATE, item)], {item: rev(item, BEGIN + 1)}, at_begin, read_set=[item]
        )
        assert len(conflicts) == 1
        assert conflicts[0].ours is not None


class TestBuildRevisions:
    def test_stamps_one_commit(self) -> None:
        new, old, gone = ItemId.new(), ItemId.new(), ItemId.new()
        latest = {old: rev(old, 5, inserted=3), gone: rev(gone, 6, inserted=2)}
        author, commit = PeerId.new(), CommitId.new()
        revisions = build_revisions(
            [change(Op.INSERT, new, b"n"), change(Op.UPDATE, old, b"u"), change(Op.REMOVE, gone)],
            latest,
            20,
            author,
            commit,
        )
        assert revisions == [
            Revision(new, "t", CHUNK, b"n", 20, 20, False, author, commit),
            Revision(old, "t", CHUNK, b"u", 3, 20, False, author, commit),
            Revision(gone, "t", CHUNK, b"", 2, 20, True, author, commit),
        ]

    def test_reinsert_after_a_tombstone_starts_a_new_life(self) -> None:
        item = ItemId.new()
        latest = {item: rev(item, 8, removed=True, inserted=2)}
        (revision,) = build_revisions(
            [change(Op.INSERT, item)], latest, 9, PeerId.new(), CommitId.new()
        )
        assert revision.insert_time == 9
        assert not revision.removed

    def test_nothing_in_nothing_out(self) -> None:
        assert build_revisions([], {}, 1, PeerId.new(), CommitId.new()) == []


# -- transactions on a real peer -----------------------------------------------

TABLE = "counters"


@dataclass
class World:
    """A peer with a counter table of two chunks and an account table."""

    peer: Peer
    chunk: ChunkId
    other_chunk: ChunkId
    accounts: ChunkId

    def counter(self, name: str, value: int) -> Message:
        return self.peer.table(TABLE).message_type(name=name, value=value)

    async def seed(self, **values: int) -> dict[str, ItemId]:
        tx = self.peer.begin()
        ids = {
            name: tx.insert(TABLE, self.counter(name, v), self.chunk) for name, v in values.items()
        }
        await tx.commit("seed")
        return ids

    async def perturb(self, item: ItemId, name: str, value: int) -> CommitRecord:
        """Someone else's committed update of `item`."""
        tx = self.peer.begin()
        tx.update(TABLE, item, self.counter(name, value))
        record = await tx.commit("perturb")
        assert record is not None
        return record

    def value_now(self, item: ItemId) -> int | None:
        revision = self.peer.read_local(item, self.peer.now())
        if revision is None or revision.removed:
            return None
        return int(self.peer.table(TABLE).decode(revision.data).value)


async def values(tx: Transaction, chunk: ChunkId | None = None) -> dict[str, int]:
    return {m.name: m.value for m in (await tx.items(TABLE, chunk)).values()}


async def value(tx: Transaction, item: ItemId) -> int | None:
    message = await tx.get(TABLE, item)
    return None if message is None else int(message.value)


@pytest.fixture(params=["memory", "sqlite"])
async def world(
    request: pytest.FixtureRequest,
    memory_peer: Peer,
    make_peer: Callable[..., Awaitable[Peer]],
) -> World:
    peer = memory_peer if request.param == "memory" else await make_peer()
    await peer.create_table(TABLE, "mapapi.v1.Counter")
    await peer.create_table("accounts", "mapapi.v1.Account")
    return World(
        peer,
        await peer.create_chunk(TABLE),
        await peer.create_chunk(TABLE),
        await peer.create_chunk("accounts"),
    )


class TestReads:
    async def test_reads_the_map_as_of_begin_time(self, world: World) -> None:
        ids = await world.seed(a=1, b=2)
        tx = world.peer.begin()
        await world.perturb(ids["a"], "a", 100)
        tx2 = world.peer.begin()
        t = world.peer.begin()
        t.remove(TABLE, ids["b"])
        await t.commit()
        assert await value(tx, ids["a"]) == 1
        assert await value(tx, ids["b"]) == 2
        assert await values(tx) == {"a": 1, "b": 2}
        assert list(await tx.find(TABLE, "name", "b")) == [ids["b"]]
        assert await values(tx2) == {"a": 100, "b": 2}
        assert await values(world.peer.begin()) == {"a": 100}

    async def test_begin_at_a_past_time_reads_history(self, world: World) -> None:
        ids = await world.seed(a=1)
        then = world.peer.now()
        await world.perturb(ids["a"], "a", 2)
        assert await value(world.peer.begin(at=then), ids["a"]) == 1
        assert await value(world.peer.begin(at=0), ids["a"]) is None

    @pytest.mark.parametrize("delta", [1, -1 - 10**6])
    async def test_begin_outside_known_time_is_refused(self, world: World, delta: int) -> None:
        await world.seed(a=1)
        with pytest.raises(UsageError, match="outside"):
            world.peer.begin(at=world.peer.now() + delta)

    async def test_missing_item_reads_as_none(self, world: World) -> None:
        tx = world.peer.begin()
        assert await tx.get(TABLE, ItemId.new()) is None

    async def test_get_through_the_wrong_table_is_refused(self, world: World) -> None:
        ids = await world.seed(a=1)
        with pytest.raises(UsageError, match="belongs to table 'counters'"):
            await world.peer.begin().get("accounts", ids["a"])

    async def test_items_of_a_foreign_chunk_are_refused(self, world: World) -> None:
        with pytest.raises(UsageError, match="does not belong"):
            await world.peer.begin().items(TABLE, world.accounts)

    async def test_own_buffered_changes_are_visible(self, world: World) -> None:
        ids = await world.seed(a=1, b=2)
        tx = world.peer.begin()
        tx.update(TABLE, ids["a"], world.counter("a", 10))
        tx.remove(TABLE, ids["b"])
        c = tx.insert(TABLE, world.counter("c", 3), world.chunk)
        assert await value(tx, ids["a"]) == 10
        assert await value(tx, ids["b"]) is None
        assert await value(tx, c) == 3
        assert await values(tx) == {"a": 10, "c": 3}
        assert list(await tx.find(TABLE, "name", "a")) == [ids["a"]]
        assert await tx.find(TABLE, "name", "b") == {}
        assert list(await tx.find(TABLE, "name", "c")) == [c]
        # Nobody else sees them before the commit.
        assert await values(world.peer.begin()) == {"a": 1, "b": 2}

    async def test_find_matches_numbers_and_defaults(self, world: World) -> None:
        ids = await world.seed(zero=0, five=5, other=5)
        tx = world.peer.begin()
        tx.update(TABLE, ids["other"], world.counter("other", 6))
        assert set(await tx.find(TABLE, "value", 5)) == {ids["five"]}
        assert set(await tx.find(TABLE, "value", 0)) == {ids["zero"]}
        assert set(await tx.find(TABLE, "value", 6)) == {ids["other"]}

    async def test_items_of_one_chunk_include_only_its_changes(self, world: World) -> None:
        await world.seed(a=1)
        tx = world.peer.begin()
        tx.insert(TABLE, world.counter("x", 7), world.other_chunk)
        assert await values(tx, world.other_chunk) == {"x": 7}
        assert await values(tx, world.chunk) == {"a": 1}
        assert await values(tx) == {"a": 1, "x": 7}


class TestWrites:
    async def test_insert_update_remove_commit(self, world: World) -> None:
        ids = await world.seed(a=1, b=2)
        tx = world.peer.begin()
        tx.update(TABLE, ids["a"], world.counter("a", 11))
        tx.remove(TABLE, ids["b"])
        c = tx.insert(TABLE, world.counter("c", 3), world.other_chunk)
        record = await tx.commit("three changes")
        assert record is not None
        assert record.message == "three changes"
        assert record.author == world.peer.id
        assert record.time > tx.begin_time
        assert record.chunks == tuple(sorted([world.chunk, world.other_chunk]))
        assert await values(world.peer.begin()) == {"a": 11, "c": 3}
        written = world.peer.commit_revisions(record.id)
        assert sorted(r.item_id for r in written) == sorted([ids["a"], ids["b"], c])
        assert {r.update_time for r in written} == {record.time}
        assert world.peer.log()[0] == record

    async def test_remove_writes_a_tombstone_and_keeps_history(self, world: World) -> None:
        ids = await world.seed(a=1, b=2)
        before = world.peer.now()
        tx = world.peer.begin()
        tx.remove(TABLE, ids["a"])
        record = await tx.commit()
        assert record is not None
        history = world.peer.history(ids["a"])
        assert [r.removed for r in history] == [False, True]
        assert history[-1].data == b""
        assert history[-1].update_time == record.time
        assert world.value_now(ids["a"]) is None
        assert await value(world.peer.begin(at=before), ids["a"]) == 1
        assert {c.id: c.items for c in world.peer.chunks(TABLE)}[world.chunk] == 1

    async def test_insert_then_remove_in_one_transaction_writes_nothing(self, world: World) -> None:
        clock = world.peer.now()
        tx = world.peer.begin()
        item = tx.insert(TABLE, world.counter("a", 1), world.chunk)
        tx.remove(TABLE, item)
        assert tx.changes == []
        assert await tx.commit() is None
        assert world.peer.now() == clock
        assert world.peer.log() == []
        assert world.peer.history(item) == []

    async def test_update_after_insert_stays_an_insert(self, world: World) -> None:
        tx = world.peer.begin()
        item = tx.insert(TABLE, world.counter("a", 1), world.chunk)
        tx.update(TABLE, item, world.counter("a", 2))
        assert [(c.op, c.item_id) for c in tx.changes] == [(Op.INSERT, item)]
        await tx.commit()
        assert world.value_now(item) == 2
        assert len(world.peer.history(item)) == 1

    async def test_insert_with_a_chosen_id(self, world: World) -> None:
        item = ItemId.new()
        tx = world.peer.begin()
        assert tx.insert(TABLE, world.counter("a", 1), world.chunk, item_id=item) == item
        await tx.commit()
        assert world.value_now(item) == 1

    async def test_update_of_a_missing_item_raises_item_not_found(self, world: World) -> None:
        tx = world.peer.begin()
        with pytest.raises(ItemNotFound, match="no item"):
            tx.update(TABLE, ItemId.new(), world.counter("a", 1))
        assert tx.changes == []

    async def test_remove_of_a_missing_item_raises_item_not_found(self, world: World) -> None:
        tx = world.peer.begin()
        with pytest.raises(ItemNotFound, match="no item"):
            tx.remove(TABLE, ItemId.new())
        assert tx.changes == []

    async def test_update_of_an_item_removed_in_the_transaction_raises(self, world: World) -> None:
        ids = await world.seed(a=1)
        tx = world.peer.begin()
        tx.remove(TABLE, ids["a"])
        with pytest.raises(ItemNotFound):
            tx.update(TABLE, ids["a"], world.counter("a", 2))

    async def test_update_of_a_removed_item_raises(self, world: World) -> None:
        ids = await world.seed(a=1)
        tx = world.peer.begin()
        tx.remove(TABLE, ids["a"])
        await tx.commit()
        with pytest.raises(ItemNotFound):
            world.peer.begin().update(TABLE, ids["a"], world.counter("a", 2))

    async def test_update_of_an_item_inserted_after_begin_raises(self, world: World) -> None:
        tx = world.peer.begin()
        ids = await world.seed(a=1)
        with pytest.raises(ItemNotFound):
            tx.update(TABLE, ids["a"], world.counter("a", 2))

    async def test_insert_into_a_chunk_of_another_table_is_refused(self, world: World) -> None:
        with pytest.raises(UsageError, match="does not belong"):
            world.peer.begin().insert(TABLE, world.counter("a", 1), world.accounts)

    async def test_insert_of_a_payload_of_the_wrong_type_is_refused(self, world: World) -> None:
        account = world.peer.table("accounts").message_type(owner="x", balance=1)
        with pytest.raises(UsageError, match=r"holds mapapi\.v1\.Counter"):
            world.peer.begin().insert(TABLE, account, world.chunk)

    async def test_inserting_the_same_id_twice_is_refused(self, world: World) -> None:
        tx = world.peer.begin()
        item = tx.insert(TABLE, world.counter("a", 1), world.chunk)
        with pytest.raises(UsageError, match="already changed"):
            tx.insert(TABLE, world.counter("a", 2), world.chunk, item_id=item)

    async def test_empty_transaction_commits_nothing(self, world: World) -> None:
        assert await world.peer.begin().commit() is None
        assert world.peer.log() == []


class TestConflicts:
    async def test_conflict_carries_base_ours_theirs(self, world: World) -> None:
        ids = await world.seed(a=1)
        tx = world.peer.begin()
        tx.update(TABLE, ids["a"], world.counter("a", 10))
        theirs_commit = await world.perturb(ids["a"], "a", 2)
        with pytest.raises(ConflictError) as caught:
            await tx.commit()
        err = caught.value
        assert err.retriable
        assert tx.state is TxState.CONFLICTED
        (conflict,) = err.conflicts
        decode = world.peer.table(TABLE).decode
        assert (conflict.table, conflict.item_id, conflict.chunk_id) == (
            TABLE,
            ids["a"],
            world.chunk,
        )
        assert conflict.base is not None
        assert decode(conflict.base.data).value == 1
        assert conflict.ours is not None
        assert conflict.ours.op is Op.UPDATE
        assert decode(conflict.ours.data).value == 10
        assert conflict.theirs.commit_id == theirs_commit.id
        assert decode(conflict.theirs.data).value == 2
        assert world.value_now(ids["a"]) == 2

    async def test_remove_against_a_foreign_update_conflicts(self, world: World) -> None:
        ids = await world.seed(a=1)
        tx = world.peer.begin()
        tx.remove(TABLE, ids["a"])
        await world.perturb(ids["a"], "a", 2)
        with pytest.raises(ConflictError) as caught:
            await tx.commit()
        (conflict,) = caught.value.conflicts
        assert conflict.ours is not None
        assert conflict.ours.op is Op.REMOVE
        assert world.value_now(ids["a"]) == 2

    async def test_update_against_a_foreign_remove_conflicts(self, world: World) -> None:
        ids = await world.seed(a=1)
        tx = world.peer.begin()
        tx.update(TABLE, ids["a"], world.counter("a", 5))
        other = world.peer.begin()
        other.remove(TABLE, ids["a"])
        await other.commit()
        with pytest.raises(ConflictError) as caught:
            await tx.commit()
        assert caught.value.conflicts[0].theirs.removed
        assert world.value_now(ids["a"]) is None

    async def test_insert_of_an_id_someone_inserted_meanwhile_conflicts(self, world: World) -> None:
        item = ItemId.new()
        tx = world.peer.begin()
        tx.insert(TABLE, world.counter("mine", 1), world.chunk, item_id=item)
        other = world.peer.begin()
        other.insert(TABLE, world.counter("theirs", 2), world.chunk, item_id=item)
        await other.commit()
        with pytest.raises(ConflictError) as caught:
            await tx.commit()
        (conflict,) = caught.value.conflicts
        assert conflict.base is None
        assert world.value_now(item) == 2

    async def test_a_conflict_writes_nothing(self, world: World) -> None:
        ids = await world.seed(a=1, b=2)
        tx = world.peer.begin()
        tx.update(TABLE, ids["a"], world.counter("a", 10))
        tx.update(TABLE, ids["b"], world.counter("b", 20))
        await world.perturb(ids["a"], "a", 3)
        log = world.peer.log()
        with pytest.raises(ConflictError):
            await tx.commit()
        assert world.peer.log() == log
        assert world.value_now(ids["b"]) == 2

    async def test_merge_keeps_exactly_the_non_conflicting_changes(self, world: World) -> None:
        ids = await world.seed(a=1, b=2, c=3)
        tx = world.peer.begin()
        tx.update(TABLE, ids["a"], world.counter("a", 10))
        tx.update(TABLE, ids["b"], world.counter("b", 20))
        tx.remove(TABLE, ids["c"])
        d = tx.insert(TABLE, world.counter("d", 4), world.chunk)
        await world.perturb(ids["a"], "a", 7)
        with pytest.raises(ConflictError) as caught:
            await tx.commit()
        err = caught.value
        merged = err.merge()
        assert merged is not tx
        assert merged.state is TxState.OPEN
        assert merged.begin_time == err.seen_at == world.peer.now()
        assert [(c.op, c.item_id) for c in merged.changes] == [
            (Op.UPDATE, ids["b"]),
            (Op.REMOVE, ids["c"]),
            (Op.INSERT, d),
        ]
        assert tx.state is TxState.ABORTED
        assert await value(merged, ids["a"]) == 7  # begun after the conflict: sees theirs
        assert await merged.commit("merged") is not None
        assert await values(world.peer.begin()) == {"a": 7, "b": 20, "d": 4}

    async def test_merged_transaction_conflicts_again_on_a_later_write(self, world: World) -> None:
        ids = await world.seed(a=1, b=2)
        tx = world.peer.begin()
        tx.update(TABLE, ids["a"], world.counter("a", 10))
        tx.update(TABLE, ids["b"], world.counter("b", 20))
        await world.perturb(ids["a"], "a", 7)
        with pytest.raises(ConflictError) as caught:
            await tx.commit()
        merged = caught.value.merge()
        await world.perturb(ids["b"], "b", 8)
        with pytest.raises(ConflictError) as again:
            await merged.commit()
        assert [c.item_id for c in again.value.conflicts] == [ids["b"]]


class TestMultiCommit:
    async def test_commit_twice_own_earlier_commit_is_not_a_conflict(self, world: World) -> None:
        tx = world.peer.begin()
        begin = tx.begin_time
        item = tx.insert(TABLE, world.counter("a", 1), world.chunk)
        first = await tx.commit("first")
        assert tx.changes == []
        assert await value(tx, item) == 1  # our own commit, though after begin
        tx.update(TABLE, item, world.counter("a", 2))
        second = await tx.commit("second")
        assert first is not None
        assert second is not None
        assert second.time > first.time
        assert tx.begin_time == begin
        assert [r.update_time for r in world.peer.history(item)] == [first.time, second.time]
        assert world.value_now(item) == 2
        assert await values(tx) == {"a": 2}

    async def test_remove_of_own_committed_insert(self, world: World) -> None:
        tx = world.peer.begin()
        item = tx.insert(TABLE, world.counter("a", 1), world.chunk)
        await tx.commit()
        tx.remove(TABLE, item)
        await tx.commit()
        assert world.value_now(item) is None
        assert await value(tx, item) is None

    async def test_foreign_change_after_our_commit_still_conflicts(self, world: World) -> None:
        ids = await world.seed(a=1)
        tx = world.peer.begin()
        tx.update(TABLE, ids["a"], world.counter("a", 2))
        await tx.commit()
        theirs = await world.perturb(ids["a"], "a", 3)
        tx.update(TABLE, ids["a"], world.counter("a", 4))
        with pytest.raises(ConflictError) as caught:
            await tx.commit()
        assert caught.value.conflicts[0].theirs.update_time == theirs.time
        assert world.value_now(ids["a"]) == 3

    async def test_foreign_change_of_an_item_we_did_not_commit_conflicts(
        self, world: World
    ) -> None:
        ids = await world.seed(a=1, b=1)
        tx = world.peer.begin()
        tx.update(TABLE, ids["a"], world.counter("a", 2))
        await tx.commit()
        await world.perturb(ids["b"], "b", 3)
        tx.update(TABLE, ids["b"], world.counter("b", 4))
        with pytest.raises(ConflictError):
            await tx.commit()


class TestSerializable:
    async def _two_accounts(self, world: World) -> tuple[ItemId, ItemId]:
        kind = world.peer.table("accounts").message_type
        tx = world.peer.begin()
        alice = tx.insert("accounts", kind(owner="alice", balance=100), world.accounts)
        bob = tx.insert("accounts", kind(owner="bob", balance=100), world.accounts)
        await tx.commit()
        return alice, bob

    async def _withdraw(self, tx: Transaction, take_from: ItemId, other: ItemId) -> None:
        """Withdraw 150 if the joint balance (read from both accounts) allows it."""
        mine, theirs = await tx.get("accounts", take_from), await tx.get("accounts", other)
        assert mine is not None
        assert theirs is not None
        if mine.balance + theirs.balance >= 150:
            mine.balance -= 150
            tx.update("accounts", take_from, mine)

    async def _total(self, world: World) -> int:
        items = await world.peer.begin().items("accounts")
        return sum(m.balance for m in items.values())

    async def test_snapshot_isolation_allows_write_skew(self, world: World) -> None:
        alice, bob = await self._two_accounts(world)
        one, two = world.peer.begin(), world.peer.begin()
        await self._withdraw(one, alice, bob)
        await self._withdraw(two, bob, alice)
        await one.commit()
        await two.commit()
        assert await self._total(world) == -100  # the anomaly serializable prevents

    async def test_serializable_catches_write_skew(self, world: World) -> None:
        alice, bob = await self._two_accounts(world)
        one = world.peer.begin(isolation="serializable")
        two = world.peer.begin(isolation="serializable")
        await self._withdraw(one, alice, bob)
        await self._withdraw(two, bob, alice)
        await one.commit()
        with pytest.raises(ConflictError) as caught:
            await two.commit()
        (conflict,) = caught.value.conflicts
        assert conflict.item_id == alice
        assert conflict.ours is None  # only read
        assert await self._total(world) == 50

    async def test_serializable_catches_a_phantom(self, world: World) -> None:
        await world.seed(a=1)
        tx = world.peer.begin(isolation="serializable")
        assert len(await tx.items(TABLE, world.chunk)) == 1
        tx.insert(TABLE, world.counter("total", 1), world.other_chunk)
        other = world.peer.begin()
        phantom = other.insert(TABLE, world.counter("late", 5), world.chunk)
        await other.commit()
        with pytest.raises(ConflictError) as caught:
            await tx.commit()
        assert [(c.item_id, c.ours) for c in caught.value.conflicts] == [(phantom, None)]

    async def test_serializable_find_catches_a_phantom(self, world: World) -> None:
        tx = world.peer.begin(isolation="serializable")
        assert await tx.find(TABLE, "name", "late") == {}
        tx.insert(TABLE, world.counter("other", 1), world.chunk)
        other = world.peer.begin()
        other.insert(TABLE, world.counter("late", 5), world.chunk)
        await other.commit()
        with pytest.raises(ConflictError):
            await tx.commit()

    async def test_writes_outside_the_scanned_range_are_no_phantom(self, world: World) -> None:
        tx = world.peer.begin(isolation="serializable")
        await tx.items(TABLE, world.chunk)
        tx.insert(TABLE, world.counter("mine", 1), world.chunk)
        other = world.peer.begin()
        other.insert(TABLE, world.counter("elsewhere", 5), world.other_chunk)
        await other.commit()
        assert await tx.commit() is not None

    async def test_read_only_serializable_commit_validates_its_reads(self, world: World) -> None:
        ids = await world.seed(a=1)
        quiet = world.peer.begin(isolation="serializable")
        await quiet.get(TABLE, ids["a"])
        assert await quiet.commit() is None
        raced = world.peer.begin(isolation="serializable")
        await raced.get(TABLE, ids["a"])
        await world.perturb(ids["a"], "a", 2)
        with pytest.raises(ConflictError):
            await raced.commit()

    async def test_own_commits_are_no_phantoms(self, world: World) -> None:
        tx = world.peer.begin(isolation="serializable")
        await tx.items(TABLE)
        tx.insert(TABLE, world.counter("a", 1), world.chunk)
        assert await tx.commit() is not None
        await tx.items(TABLE)
        tx.insert(TABLE, world.counter("b", 2), world.chunk)
        assert await tx.commit() is not None
        assert await values(world.peer.begin()) == {"a": 1, "b": 2}

    async def test_unknown_isolation_is_refused(self, world: World) -> None:
        with pytest.raises(UsageError, match="isolation"):
            world.peer.begin(isolation="chaos")  # type: ignore[arg-type]


class TestTxState:
    async def _conflicted(self, world: World) -> tuple[Transaction, ItemId]:
        ids = await world.seed(a=1)
        tx = world.peer.begin()
        tx.update(TABLE, ids["a"], world.counter("a", 2))
        await world.perturb(ids["a"], "a", 3)
        with pytest.raises(ConflictError):
            await tx.commit()
        return tx, ids["a"]

    async def test_open_until_conflicted(self, world: World) -> None:
        tx = world.peer.begin()
        assert tx.state is TxState.OPEN
        tx.insert(TABLE, world.counter("a", 1), world.chunk)
        await tx.commit()
        assert tx.state is TxState.OPEN

    async def test_conflicted_refuses_commit_and_changes(self, world: World) -> None:
        tx, item = await self._conflicted(world)
        with pytest.raises(ViewClosedError, match=r"CONFLICTED -> VALIDATING.*merge"):
            await tx.commit()
        with pytest.raises(ViewClosedError):
            tx.update(TABLE, item, world.counter("a", 9))
        with pytest.raises(ViewClosedError):
            tx.insert(TABLE, world.counter("b", 9), world.chunk)
        assert tx.state is TxState.CONFLICTED
        assert world.value_now(item) == 3

    async def test_conflicted_can_abort(self, world: World) -> None:
        tx, _ = await self._conflicted(world)
        tx.abort()
        assert tx.state is TxState.ABORTED

    async def test_aborted_refuses_everything(self, world: World) -> None:
        ids = await world.seed(a=1)
        tx = world.peer.begin()
        tx.update(TABLE, ids["a"], world.counter("a", 2))
        tx.abort()
        assert tx.state is TxState.ABORTED
        assert tx.changes == []
        with pytest.raises(ViewClosedError, match="ABORTED -> VALIDATING"):
            await tx.commit()
        with pytest.raises(ViewClosedError):
            tx.remove(TABLE, ids["a"])
        with pytest.raises(ViewClosedError):
            tx.insert(TABLE, world.counter("b", 1), world.chunk)
        with pytest.raises(ViewClosedError):
            tx.abort()
        assert world.value_now(ids["a"]) == 1

    async def test_original_refuses_commit_after_merge(self, world: World) -> None:
        ids = await world.seed(a=1)
        tx = world.peer.begin()
        tx.update(TABLE, ids["a"], world.counter("a", 2))
        await world.perturb(ids["a"], "a", 3)
        with pytest.raises(ConflictError) as caught:
            await tx.commit()
        caught.value.merge()
        assert tx.state is TxState.ABORTED
        with pytest.raises(ViewClosedError):
            await tx.commit()
