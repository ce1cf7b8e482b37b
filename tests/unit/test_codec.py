"""Core dataclasses to protobuf and back (mapapi.core.codec)."""

import pytest

from mapapi.core import codec
from mapapi.core.change import Change, Conflict, Op
from mapapi.core.errors import CorruptRepoError
from mapapi.core.history import Revision
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId
from mapapi.core.table import message_class
from mapapi.core.view import View

CHUNK = ChunkId.new()
ViewState = message_class("mapapi.v1.ViewState")


def revision(*, removed: bool = False, time: int = 7) -> Revision:
    return Revision(
        ItemId.new(),
        "poses",
        CHUNK,
        b"" if removed else b"\x08\x01payload\x00\xff",
        3,
        time,
        removed,
        PeerId.new(),
        CommitId.new(),
    )


def change(op: Op, data: bytes = b"\x01\x02") -> Change:
    return Change(op, "poses", ItemId.new(), CHUNK, b"" if op is Op.REMOVE else data)


class TestRevision:
    @pytest.mark.parametrize("removed", [False, True])
    def test_round_trip(self, removed: bool) -> None:
        original = revision(removed=removed)
        assert codec.revision_from_pb(codec.revision_to_pb(original)) == original

    def test_round_trip_through_bytes(self) -> None:
        original = revision(time=2**40)
        wire = codec.revision_to_pb(original).SerializeToString()
        parsed = type(codec.revision_to_pb(original))()
        parsed.ParseFromString(wire)
        assert codec.revision_from_pb(parsed) == original

    def test_ids_travel_as_16_bytes(self) -> None:
        original = revision()
        message = codec.revision_to_pb(original)
        assert message.item_id == original.item_id.to_bytes()
        assert len(message.chunk_id) == len(message.author) == len(message.commit_id) == 16

    def test_bad_id_length_is_refused(self) -> None:
        message = codec.revision_to_pb(revision())
        message.item_id = b"\x01\x02"
        with pytest.raises(ValueError, match="16 bytes"):
            codec.revision_from_pb(message)


class TestChange:
    @pytest.mark.parametrize("op", list(Op))
    def test_round_trip(self, op: Op) -> None:
        original = change(op)
        assert codec.change_from_pb(codec.change_to_pb(original)) == original

    def test_op_values_match_the_proto_enum(self) -> None:
        for op in Op:
            message = codec.change_to_pb(change(op))
            assert (
                message.DESCRIPTOR.fields_by_name["op"].enum_type.values_by_number[message.op].name
                == op.name
            )


class TestView:
    def test_round_trip_with_changes_and_conflicts(self) -> None:
        theirs, gone, base = revision(), revision(removed=True), revision(time=2)
        changes = [change(Op.INSERT), change(Op.UPDATE), change(Op.REMOVE)]
        conflicts = [
            Conflict("poses", theirs.item_id, CHUNK, base, change(Op.UPDATE), theirs),
            Conflict("poses", gone.item_id, CHUNK, None, None, gone),
        ]
        reads = {theirs.item_id, ItemId.new()}
        scopes = {("poses", CHUNK), ("poses", None)}
        view = View("main", 42, "serializable", changes, conflicts, reads, scopes)
        assert codec.decode_view(codec.encode_view(view)) == view

    def test_empty_view(self) -> None:
        view = View("scratch", 0)
        assert codec.decode_view(codec.encode_view(view)) == view

    @pytest.mark.parametrize(
        "blob",
        [
            b"\x0a\xff",  # a string whose length runs past the end
            b"\xff\xff\xff\xff\xff\xff\xff\xff\xff\xff\xff",  # a varint that never ends
            b"not a view at all, just some text",
        ],
    )
    def test_garbage_blob_is_corrupt(self, blob: bytes) -> None:
        with pytest.raises(CorruptRepoError, match="does not parse"):
            codec.decode_view(blob)

    def test_blob_with_a_bad_id_is_corrupt(self) -> None:
        view = ViewState()
        view.ParseFromString(codec.encode_view(View("main", 1, changes=[change(Op.UPDATE)])))
        view.changes[0].item_id = b"\x01\x02\x03"
        with pytest.raises(CorruptRepoError, match="16 bytes"):
            codec.decode_view(view.SerializeToString())

    @pytest.mark.parametrize("op", [0, 9])
    def test_blob_with_an_unknown_op_is_corrupt(self, op: int) -> None:
        view = ViewState()
        view.ParseFromString(codec.encode_view(View("main", 1, changes=[change(Op.UPDATE)])))
        view.changes[0].op = op
        with pytest.raises(CorruptRepoError):
            codec.decode_view(view.SerializeToString())

    def test_conflict_without_theirs_is_corrupt(self) -> None:
        conflict = Conflict("poses", ItemId.new(), CHUNK, None, None, revision())
        view = ViewState()
        view.ParseFromString(codec.encode_view(View("main", 1, "snapshot", [], [conflict])))
        view.conflicts[0].ClearField("theirs")
        with pytest.raises(CorruptRepoError):
            codec.decode_view(view.SerializeToString())
