"""Subscription specs (mapapi.swarm.subscriptions): parsing `--where`, the stored form,
and which revisions match, on pure data (no ring)."""

from __future__ import annotations

import os

import pytest
from google.protobuf import struct_pb2

from mapapi.core.errors import UsageError
from mapapi.core.history import Revision
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId
from mapapi.core.table import TableDescriptor
from mapapi.lookup.spatial import BBox
from mapapi.lookup.spatial_index import encode_filter
from mapapi.swarm.subscriptions import SubscriptionSpec, parse_where, region_filter

ROOMS = TableDescriptor.named("rooms", "google.protobuf.Struct")
ITEM = ItemId.new()
REGION = BBox(0, 0, 0, 10, 10, 3)


def revision(time: int, fields: dict[str, object] | None, *, first: int = 1) -> Revision:
    """A revision of ITEM in table rooms (None: a removal)."""
    data = b""
    if fields is not None:
        item = struct_pb2.Struct()
        item.update(fields)
        data = ROOMS.encode(item)
    return Revision(
        ITEM,
        "rooms",
        ChunkId.new(),
        data,
        first,
        time,
        fields is None,
        PeerId.new(),
        CommitId.new(),
    )


def at(x: float, **more: object) -> dict[str, object]:
    return {"bbox": [x, x, 0, x + 1, x + 1, 1], **more}


class TestParseWhere:
    @pytest.mark.parametrize(
        ("text", "expected"),
        [
            ("kind=door", ("kind", "door")),
            ("floor=2", ("floor", 2)),
            ("open=true", ("open", True)),
            ('name="a=b"', ("name", "a=b")),
            ("label=", ("label", "")),
            (" kind = door", ("kind", " door")),
        ],
    )
    def test_values_are_json_else_strings(self, text: str, expected: tuple[str, object]) -> None:
        assert parse_where(text) == expected

    @pytest.mark.parametrize("text", ["kind", "=door", " =1"])
    def test_a_filter_needs_a_field_and_an_equals_sign(self, text: str) -> None:
        with pytest.raises(UsageError, match="FIELD=VALUE"):
            parse_where(text)


class TestMatches:
    def test_inside_before_or_after_counts(self) -> None:
        spec = SubscriptionSpec(REGION)
        assert spec.matches(ROOMS, revision(1, at(1)), None)
        assert not spec.matches(ROOMS, revision(1, at(50)), None)
        assert spec.matches(ROOMS, revision(2, at(50)), revision(1, at(1)))  # left the region
        assert spec.matches(ROOMS, revision(2, None), revision(1, at(1)))  # removed from it
        assert not spec.matches(ROOMS, revision(2, None), revision(1, at(50)))

    def test_table_and_fields(self) -> None:
        spec = SubscriptionSpec(REGION, "rooms", (("kind", "door"), ("floor", 1)))
        assert spec.matches(ROOMS, revision(1, at(1, kind="door", floor=1)), None)
        assert not spec.matches(ROOMS, revision(1, at(1, kind="door", floor=2)), None)
        assert not spec.matches(ROOMS, revision(1, at(1, floor=1)), None)
        other = SubscriptionSpec(REGION, "notes")
        assert not other.matches(ROOMS, revision(1, at(1)), None)
        # a removal is judged by what the item was
        removal = revision(2, None)
        assert spec.matches(ROOMS, removal, revision(1, at(1, kind="door", floor=1)))

    def test_items_without_a_box_never_match(self) -> None:
        assert not SubscriptionSpec(REGION).matches(ROOMS, revision(1, {"kind": "door"}), None)


class TestStoredForm:
    def test_round_trip(self) -> None:
        spec = SubscriptionSpec(REGION, "rooms", (("kind", "door"), ("floor", 1.0)))
        message = spec.to_pb(os.urandom(16), PeerId.new(), "tcp://127.0.0.1:5")
        assert SubscriptionSpec.from_pb(message) == spec

    def test_the_region_filter_keeps_overlapping_regions(self) -> None:
        stored = SubscriptionSpec(REGION).to_pb(os.urandom(16), PeerId.new(), "tcp://x:1")
        raw = stored.SerializeToString()
        assert region_filter(encode_filter(BBox(10, 10, 3, 20, 20, 4)))(raw)
        assert not region_filter(encode_filter(BBox(11, 0, 0, 20, 20, 4)))(raw)
        assert not region_filter(encode_filter(REGION))(b"\xff garbage")
        with pytest.raises(ValueError, match="box"):
            region_filter(b"")
