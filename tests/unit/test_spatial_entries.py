"""Spatial index entries and the "bbox" filter (mapapi.lookup.spatial_index), and where
items lie by type (mapapi.lookup.extent): pure functions, no ring."""

from __future__ import annotations

from collections.abc import Callable

import pytest
from google.protobuf import struct_pb2

from mapapi._pb.mapapi.v1 import lookup_pb2, maps_pb2
from mapapi.core.errors import InvalidBBox
from mapapi.core.ids import ChunkId, PeerId
from mapapi.lookup.extent import extent_of, item_box
from mapapi.lookup.spatial import BBox
from mapapi.lookup.spatial_index import SpatialRef, bbox_filter, decode_filter, encode_filter
from mapapi.swarm.subscriptions import region_filter

CHUNK = ChunkId("0123456789abcdef0123456789abcdef")
HOLDER = (PeerId("fedcba9876543210fedcba9876543210"), "tcp://10.0.0.7:7000")


def ref(*bbox: float, table: str = "rooms", missions: tuple[str, ...] = ()) -> SpatialRef:
    return SpatialRef(CHUNK, table, BBox(*bbox), missions, (HOLDER,))


class TestEntries:
    def test_round_trip(self) -> None:
        original = ref(-1.5, 0, 0, 2, 3.25, 1, missions=("b", "a"))
        decoded = SpatialRef.decode(original.encode())
        assert decoded == SpatialRef(CHUNK, "rooms", original.bbox, ("a", "b"), (HOLDER,))

    def test_equal_refs_encode_to_equal_bytes(self) -> None:
        one = ref(0, 0, 0, 1, 1, 1, missions=("x", "y")).encode()
        other = ref(0, 0, 0, 1, 1, 1, missions=("y", "x")).encode()
        assert one == other

    def test_an_entry_names_exactly_one_holder(self) -> None:
        with pytest.raises(ValueError, match="one holder"):
            SpatialRef(CHUNK, "rooms", BBox(0, 0, 0, 1, 1, 1)).encode()

    @pytest.mark.parametrize("raw", [b"\xff\xff\xff", b"", b"\x0a\x03abc"])
    def test_garbage_is_no_entry(self, raw: bytes) -> None:
        with pytest.raises(ValueError, match="spatial entry"):
            SpatialRef.decode(raw)


class TestBboxFilter:
    def test_keeps_overlapping_entries_of_the_table(self) -> None:
        keep = bbox_filter(encode_filter(BBox(1, 1, 1, 2, 2, 2), "rooms"))
        assert keep(ref(0, 0, 0, 1, 1, 1).encode())  # touching a corner
        assert not keep(ref(3, 3, 3, 4, 4, 4).encode())
        assert not keep(ref(0, 0, 0, 5, 5, 5, table="clouds").encode())

    def test_without_a_table_any_table_passes(self) -> None:
        keep = bbox_filter(encode_filter(BBox(0, 0, 0, 1, 1, 1)))
        assert keep(ref(0, 0, 0, 5, 5, 5, table="clouds").encode())

    def test_members_that_are_no_entries_are_dropped(self) -> None:
        keep = bbox_filter(encode_filter(BBox(0, 0, 0, 1, 1, 1)))
        assert not keep(b"\x00" * 16 + b"tcp://127.0.0.1:1")  # a holder entry

    @pytest.mark.parametrize("argument", [b"\xff\xff", b""])
    @pytest.mark.parametrize("member_filter", [bbox_filter, region_filter])
    def test_a_bad_argument_is_refused(
        self, argument: bytes, member_filter: Callable[[bytes], object]
    ) -> None:
        with pytest.raises(ValueError, match="spatial filter"):
            member_filter(argument)

    def test_one_parser_reads_what_encode_filter_wrote(self) -> None:
        box = BBox(0, 1, 2, 3, 4, 5)
        assert decode_filter(encode_filter(box, "rooms")) == (box, "rooms")
        assert decode_filter(encode_filter(box)) == (box, None)
        inverted = maps_pb2.Box3(xmin=1, xmax=0)
        with pytest.raises(InvalidBBox):
            decode_filter(lookup_pb2.SpatialFilter(bbox=inverted).SerializeToString())


def struct(**fields: object) -> struct_pb2.Struct:
    item = struct_pb2.Struct()
    item.update(fields)
    return item


class TestExtent:
    def test_a_struct_with_six_numbers_in_bbox_is_placed(self) -> None:
        assert item_box(struct(bbox=[0, 1, 2, 3, 4, 5])) == BBox(0, 1, 2, 3, 4, 5)

    @pytest.mark.parametrize(
        "fields",
        [
            {},
            {"bbox": [0, 1, 2]},
            {"bbox": "0 1 2 3 4 5"},
            {"bbox": [0, 1, 2, 3, 4, "5"]},
            {"bbox": [5, 1, 2, 3, 4, 5]},  # xmin > xmax: not a box
        ],
    )
    def test_a_struct_without_a_valid_bbox_is_not_placed(self, fields: dict[str, object]) -> None:
        assert item_box(struct(**fields)) is None

    def test_map_types(self) -> None:
        box = maps_pb2.Box3(xmin=-1, ymin=-2, zmin=0, xmax=3, ymax=4, zmax=1)
        mission = maps_pb2.Mission(name="tunnel-a", bbox=box)
        assert item_box(mission) == BBox(-1, -2, 0, 3, 4, 1)
        assert item_box(maps_pb2.Mission(name="empty")) is None
        extent = extent_of("mapapi.v1.Mission")
        assert extent is not None
        assert extent.label is not None
        assert extent.label(mission) == "tunnel-a"
        vertex = maps_pb2.Vertex(pose=maps_pb2.Pose3(x=1, y=2, z=3))
        assert item_box(vertex) == BBox.around((1, 2, 3))
        assert item_box(maps_pb2.Edge()) is None

    def test_a_malformed_box_in_a_map_item_raises(self) -> None:
        bad = maps_pb2.Mission(bbox=maps_pb2.Box3(xmin=2, xmax=1))
        with pytest.raises(InvalidBBox):
            item_box(bad)
