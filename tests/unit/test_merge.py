"""Auto-merge policies for update/update conflicts (mapapi.core.merge, DESIGN §5 step 5)."""

from collections.abc import Awaitable, Callable
from typing import Any

import pytest
from google.protobuf import json_format, struct_pb2, wrappers_pb2
from google.protobuf.message import Message

from mapapi import ChunkId, ConflictError, ItemId, Peer, UsageError
from mapapi.core.merge import disjoint_fields
from mapapi.core.table import message_class


def struct(**fields: Any) -> struct_pb2.Struct:
    message = struct_pb2.Struct()
    message.update(fields)
    return message


def as_dict(message: Message) -> Any:
    return json_format.MessageToDict(message, preserving_proto_field_name=True)


Counter = message_class("mapapi.v1.Counter")


class TestDisjointFields:
    def test_changes_to_different_fields_merge(self) -> None:
        base = struct(x=1, y=1, note="a")
        merged = disjoint_fields(base, struct(x=5, y=1, note="a"), struct(x=1, y=7, note="a"))
        assert merged is not None
        assert as_dict(merged) == {"x": 5, "y": 7, "note": "a"}

    def test_added_and_removed_fields_merge(self) -> None:
        base = struct(x=1, gone=True)
        merged = disjoint_fields(base, struct(x=1), struct(x=1, gone=True, new="n"))
        assert merged is not None
        assert as_dict(merged) == {"x": 1, "new": "n"}

    def test_same_field_changed_by_both_conflicts(self) -> None:
        base = struct(x=1, y=1)
        assert disjoint_fields(base, struct(x=2, y=1), struct(x=3, y=1)) is None

    def test_equal_edits_of_the_same_field_still_conflict(self) -> None:
        base = struct(x=1, y=1)
        assert disjoint_fields(base, struct(x=2, y=1), struct(x=2, y=1)) is None

    def test_no_base_means_no_merge(self) -> None:
        assert disjoint_fields(None, struct(x=1), struct(y=1)) is None

    def test_only_our_change_wins_over_an_untouched_theirs(self) -> None:
        base = struct(x=1)
        merged = disjoint_fields(base, struct(x=2), struct(x=1))
        assert merged is not None
        assert as_dict(merged) == {"x": 2}

    def test_typed_messages_keep_their_type(self) -> None:
        base = Counter(name="a", value=10)
        merged = disjoint_fields(base, Counter(name="b", value=10), Counter(name="a", value=11))
        assert isinstance(merged, Counter)
        assert (merged.name, merged.value) == ("b", 11)

    def test_change_to_a_default_value_is_a_change(self) -> None:
        base = Counter(name="a", value=10)
        merged = disjoint_fields(base, Counter(name="a", value=0), Counter(name="z", value=10))
        assert merged is not None
        assert (merged.name, merged.value) == ("z", 0)

    def test_wrapper_payload_changed_on_one_side_merges(self) -> None:
        base = wrappers_pb2.Int64Value(value=1)
        ours = wrappers_pb2.Int64Value(value=2)
        assert disjoint_fields(base, ours, wrappers_pb2.Int64Value(value=1)) == ours
        assert disjoint_fields(base, wrappers_pb2.Int64Value(value=1), ours) == ours

    def test_wrapper_payload_changed_on_both_sides_conflicts(self) -> None:
        base = wrappers_pb2.Int64Value(value=1)
        ours, theirs = wrappers_pb2.Int64Value(value=2), wrappers_pb2.Int64Value(value=3)
        assert disjoint_fields(base, ours, theirs) is None


def add_increments(base: Message | None, ours: Message, theirs: Message) -> Message | None:
    """A counter policy: both sides' increments add up (paper Algorithm 1)."""
    if base is None or ours.name != theirs.name:
        return None
    return Counter(name=ours.name, value=ours.value + theirs.value - base.value)


@pytest.fixture(params=["memory", "sqlite"])
async def peer(
    request: pytest.FixtureRequest,
    memory_peer: Peer,
    make_peer: Callable[..., Awaitable[Peer]],
) -> Peer:
    peer = memory_peer if request.param == "memory" else await make_peer()
    await peer.create_table("poses", "google.protobuf.Struct")
    await peer.create_table("counters", "mapapi.v1.Counter")
    return peer


async def seed(peer: Peer, table: str, message: Message) -> tuple[ItemId, ChunkId]:
    chunk = await peer.create_chunk(table)
    tx = peer.begin()
    item = tx.insert(table, message, chunk)
    await tx.commit()
    return item, chunk


async def race(peer: Peer, table: str, item: ItemId, ours: Message, theirs: Message) -> Any:
    """Commit `theirs` between our begin and our commit of `ours`; our record."""
    tx = peer.begin()
    tx.update(table, item, ours)
    other = peer.begin()
    other.update(table, item, theirs)
    await other.commit("theirs")
    return await tx.commit("ours")


def now(peer: Peer, table: str, item: ItemId) -> Any:
    revision = peer.read_local(item, peer.now())
    assert revision is not None
    return as_dict(peer.table(table).decode(revision.data))


class TestMergePolicyOnPeer:
    async def test_policy_resolves_an_update_update_conflict(self, peer: Peer) -> None:
        item, _ = await seed(peer, "poses", struct(x=1, y=1, note="a"))
        peer.set_merge_policy("poses", disjoint_fields)
        record = await race(peer, "poses", item, struct(x=5, y=1, note="a"), struct(x=1, y=7))
        assert record is not None
        assert now(peer, "poses", item) == {"x": 5, "y": 7}
        (written,) = peer.commit_revisions(record.id)
        assert as_dict(peer.table("poses").decode(written.data)) == {"x": 5, "y": 7}

    async def test_equal_concurrent_edits_of_one_field_still_conflict(self, peer: Peer) -> None:
        item, _ = await seed(peer, "poses", struct(x=1, y=1))
        peer.set_merge_policy("poses", disjoint_fields)
        with pytest.raises(ConflictError) as caught:
            await race(peer, "poses", item, struct(x=2, y=1), struct(x=2, y=1))
        assert [c.item_id for c in caught.value.conflicts] == [item]

    async def test_without_a_policy_the_same_race_conflicts(self, peer: Peer) -> None:
        item, _ = await seed(peer, "poses", struct(x=1, y=1))
        with pytest.raises(ConflictError):
            await race(peer, "poses", item, struct(x=5, y=1), struct(x=1, y=7))
        assert now(peer, "poses", item) == {"x": 1, "y": 7}

    async def test_removing_the_policy_restores_conflicts(self, peer: Peer) -> None:
        item, _ = await seed(peer, "poses", struct(x=1, y=1))
        peer.set_merge_policy("poses", disjoint_fields)
        peer.set_merge_policy("poses", None)
        with pytest.raises(ConflictError):
            await race(peer, "poses", item, struct(x=5, y=1), struct(x=1, y=7))

    async def test_policy_applies_to_its_table_only(self, peer: Peer) -> None:
        item, _ = await seed(peer, "counters", Counter(name="a", value=1))
        peer.set_merge_policy("poses", disjoint_fields)
        with pytest.raises(ConflictError):
            await race(
                peer, "counters", item, Counter(name="b", value=1), Counter(name="a", value=2)
            )

    async def test_custom_policy_adds_concurrent_increments(self, peer: Peer) -> None:
        item, _ = await seed(peer, "counters", Counter(name="hits", value=10))
        peer.set_merge_policy("counters", add_increments)
        await race(
            peer, "counters", item, Counter(name="hits", value=13), Counter(name="hits", value=15)
        )
        assert now(peer, "counters", item) == {"name": "hits", "value": "18"}

    async def test_policy_is_not_asked_about_removals(self, peer: Peer) -> None:
        item, _ = await seed(peer, "poses", struct(x=1, y=1))
        peer.set_merge_policy("poses", disjoint_fields)
        tx = peer.begin()
        tx.update("poses", item, struct(x=5, y=1))
        other = peer.begin()
        other.remove("poses", item)
        await other.commit()
        with pytest.raises(ConflictError):
            await tx.commit()

    async def test_policy_for_an_unknown_table_is_refused(self, peer: Peer) -> None:
        with pytest.raises(UsageError, match="no table 'nope'"):
            peer.set_merge_policy("nope", disjoint_fields)
