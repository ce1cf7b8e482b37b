"""Tables: a name bound to a protobuf type, JSON in and out (mapapi.core.table)."""

import json
from typing import Any

import pytest
from google.protobuf import struct_pb2, wrappers_pb2

from mapapi import TableDescriptor, UsageError
from mapapi.core.table import BUILTIN_TYPES, message_class


class TestMessageClass:
    @pytest.mark.parametrize("type_name", BUILTIN_TYPES)
    def test_every_builtin_is_known(self, type_name: str) -> None:
        cls = message_class(type_name)
        assert cls.DESCRIPTOR.full_name == type_name

    def test_struct_is_the_well_known_type(self) -> None:
        assert message_class("google.protobuf.Struct") is struct_pb2.Struct

    def test_counter_has_its_fields(self) -> None:
        counter = message_class("mapapi.v1.Counter")(name="hits", value=3)
        assert (counter.name, counter.value) == ("hits", 3)

    @pytest.mark.parametrize(
        "type_name",
        ["", "Counter", "mapapi.v1.Nope", "google.protobuf", "mapapi.v1.Change.Op"],
    )
    def test_unknown_type_is_a_usage_error(self, type_name: str) -> None:
        with pytest.raises(UsageError, match="unknown message type") as caught:
            message_class(type_name)
        assert "google.protobuf.Struct" in str(caught.value)  # lists the built-ins


COUNTERS = TableDescriptor.named("counters", "mapapi.v1.Counter")
NOTES = TableDescriptor.named("notes", "google.protobuf.Struct")


class TestDescriptor:
    def test_named_looks_up_the_type(self) -> None:
        assert COUNTERS.name == "counters"
        assert COUNTERS.type_name == "mapapi.v1.Counter"
        assert NOTES.message_type is struct_pb2.Struct

    def test_equal_by_name_and_type(self) -> None:
        assert TableDescriptor.named("counters", "mapapi.v1.Counter") == COUNTERS
        assert TableDescriptor("counters", struct_pb2.Struct) != COUNTERS

    def test_encode_decode_round_trip(self) -> None:
        message = COUNTERS.message_type(name="a", value=-7)
        assert COUNTERS.decode(COUNTERS.encode(message)) == message

    def test_encode_is_deterministic(self) -> None:
        a = NOTES.from_json('{"b": 1, "a": {"y": 2, "x": 3}}')
        b = NOTES.from_json('{"a": {"x": 3, "y": 2}, "b": 1}')
        assert NOTES.encode(a) == NOTES.encode(b)

    def test_encode_refuses_a_message_of_another_type(self) -> None:
        with pytest.raises(
            UsageError, match=r"holds mapapi\.v1\.Counter, not google\.protobuf\.Struct"
        ):
            COUNTERS.encode(struct_pb2.Struct())
        with pytest.raises(UsageError, match=r"not google\.protobuf\.Int64Value"):
            COUNTERS.encode(wrappers_pb2.Int64Value(value=1))

    def test_decode_of_garbage_is_a_usage_error(self) -> None:
        with pytest.raises(UsageError, match="does not parse"):
            COUNTERS.decode(b"\x0a\xff")


class TestJson:
    def test_from_json_fills_the_message(self) -> None:
        message = COUNTERS.from_json('{"name": "a", "value": "12"}')
        assert (message.name, message.value) == ("a", 12)

    def test_struct_takes_any_object(self) -> None:
        message = NOTES.from_json('{"text": "hi", "tags": ["a"], "pose": {"x": 1.5}}')
        assert NOTES.to_dict(message) == {"text": "hi", "tags": ["a"], "pose": {"x": 1.5}}

    @pytest.mark.parametrize("text", ["{", "", "{'single': 1}", "[1, 2", "nope"])
    def test_bad_json_is_a_usage_error(self, text: str) -> None:
        with pytest.raises(UsageError, match="does not fit table 'notes'"):
            NOTES.from_json(text)

    @pytest.mark.parametrize(
        "text", ['{"nope": 1}', '{"value": "abc"}', "[1]", "5", '{"name": 5}', "null"]
    )
    def test_json_of_the_wrong_shape_is_a_usage_error(self, text: str) -> None:
        with pytest.raises(UsageError, match=r"counters.*mapapi.v1.Counter"):
            COUNTERS.from_json(text)

    def test_to_dict_uses_proto_field_names(self) -> None:
        message = COUNTERS.message_type(name="a", value=5)
        assert COUNTERS.to_dict(message) == {"name": "a", "value": 5}
        assert COUNTERS.data_to_dict(COUNTERS.encode(message)) == {"name": "a", "value": 5}


VERTICES = TableDescriptor.named("vertices", "mapapi.v1.Vertex")
EDGES = TableDescriptor.named("edges", "mapapi.v1.Edge")
MISSIONS = TableDescriptor.named("missions", "mapapi.v1.Mission")


def field_names(table: TableDescriptor) -> set[str]:
    return {f.name for f in table.message_type.DESCRIPTOR.fields}


class TestPlainJson:
    """`to_dict` is plain JSON for scripts (issue 15), not protobuf's canonical
    mapping: 64-bit integers are numbers and fields at their default are present."""

    def test_a_64_bit_integer_is_a_number(self) -> None:
        value = COUNTERS.to_dict(COUNTERS.from_json('{"name": "a", "value": "2"}'))
        assert value == {"name": "a", "value": 2}
        assert type(value["value"]) is int

    def test_fields_at_their_default_are_present(self) -> None:
        assert COUNTERS.to_dict(COUNTERS.from_json("{}")) == {"name": "", "value": 0}

    def test_index_0_is_present_and_an_int(self) -> None:
        value = VERTICES.to_dict(VERTICES.from_json('{"mission": "m", "index": 0}'))
        assert set(value) == field_names(VERTICES)  # every field, in declaration order
        assert list(value) == [f.name for f in VERTICES.message_type.DESCRIPTOR.fields]
        assert (value["mission"], value["index"], value["timestamp"]) == ("m", 0, 0.0)
        assert type(value["index"]) is int
        assert value["pose"] is None  # an unset message field is null

    def test_nested_repeated_and_enum_fields(self) -> None:
        edge = EDGES.from_json('{"from_vertex": {"index": "7"}, "information": [1, 2], "kind": 2}')
        value = EDGES.to_dict(edge)
        assert set(value) == field_names(EDGES)
        assert value["from_vertex"] == {"mission": "", "index": 7}
        assert (value["to_vertex"], value["relative"]) == (None, None)
        assert (value["information"], value["kind"]) == ([1.0, 2.0], "LOOP")

    def test_map_fields_keep_their_keys(self) -> None:
        mission = MISSIONS.from_json('{"name": "m", "chunks": {"vertices": "ab"}}')
        assert MISSIONS.to_dict(mission)["chunks"] == {"vertices": "ab"}

    @pytest.mark.parametrize(
        ("type_name", "text", "wanted"),
        [
            ("google.protobuf.Int64Value", '"-5"', -5),
            ("google.protobuf.Int64Value", "0", 0),
            ("google.protobuf.DoubleValue", "0", 0.0),
            ("google.protobuf.StringValue", '""', ""),
        ],
    )
    def test_wrappers_are_bare_values(self, type_name: str, text: str, wanted: Any) -> None:
        table = TableDescriptor.named("w", type_name)
        value = table.to_dict(table.from_json(text))
        assert (value, type(value)) == (wanted, type(wanted))

    def test_struct_integers_stay_integers(self) -> None:
        value = NOTES.to_dict(NOTES.from_json('{"n": 1, "x": 1.5, "l": [0, {"z": 2}]}'))
        assert json.dumps(value) == '{"l": [0, {"z": 2}], "n": 1, "x": 1.5}'

    @pytest.mark.parametrize(
        ("table", "text"),
        [
            (COUNTERS, '{"name": "a", "value": 9007199254740993}'),
            (VERTICES, '{"mission": "m", "index": 3, "pose": {"x": 1.5, "qw": 1}}'),
            (EDGES, '{"from_vertex": {"index": 1}, "to_vertex": {"index": 2}, "kind": 1}'),
            (NOTES, '{"a": [1, "b", null, true]}'),
        ],
    )
    def test_plain_json_reads_back_as_the_same_message(
        self, table: TableDescriptor, text: str
    ) -> None:
        message = table.from_json(text)
        assert table.from_json(json.dumps(table.to_dict(message))) == message


class TestFieldJson:
    @pytest.mark.parametrize(
        ("json_text", "field", "wanted"),
        [
            ('{"name": "a", "value": 5}', "value", 5),
            ('{"name": "a"}', "value", 0),  # an unset proto3 scalar is its default
            ('{"value": 5}', "name", ""),
            ('{"name": "a", "value": "-9223372036854775808"}', "value", -(2**63)),
        ],
    )
    def test_typed_fields_compare_as_json_values(
        self, json_text: str, field: str, wanted: Any
    ) -> None:
        message = COUNTERS.from_json(json_text)
        assert COUNTERS.field_json(message, field) == COUNTERS.canonical_json(wanted)

    @pytest.mark.parametrize(
        ("json_text", "field", "wanted"),
        [
            ('{"x": 1}', "x", 1),
            ('{"x": 1}', "x", 1.0),
            ('{"x": 1.5}', "x", 1.5),
            ('{"p": {"b": 2, "a": [1, true]}}', "p", {"a": [1, True], "b": 2.0}),
            ('{"x": null}', "x", None),
            ('{"x": "s"}', "x", "s"),
        ],
    )
    def test_struct_fields_compare_as_json_values(
        self, json_text: str, field: str, wanted: Any
    ) -> None:
        message = NOTES.from_json(json_text)
        assert NOTES.field_json(message, field) == NOTES.canonical_json(wanted)

    @pytest.mark.parametrize(("value", "other"), [(1, True), (1, "1"), (0, None), (1.5, 1)])
    def test_different_values_stay_different(self, value: Any, other: Any) -> None:
        assert NOTES.canonical_json(value) != NOTES.canonical_json(other)

    def test_absent_field_is_null(self) -> None:
        assert NOTES.field_value(NOTES.from_json('{"x": 1}'), "y") is None
        assert COUNTERS.field_value(COUNTERS.from_json("{}"), "nope") is None
