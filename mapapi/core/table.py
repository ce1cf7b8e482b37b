"""Tables: a name bound to a protobuf message type, with JSON in and out."""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

from google.protobuf import json_format, message_factory, struct_pb2, wrappers_pb2
from google.protobuf.descriptor import Descriptor, FieldDescriptor
from google.protobuf.descriptor_pool import Default as _default_pool
from google.protobuf.message import DecodeError, Message

from mapapi.core import limits
from mapapi.core.errors import CorruptPayload, UsageError

# Imported for their side effect: they register the built-in types in the pool.
_BUILTIN_MODULES = (struct_pb2, wrappers_pb2)
BUILTIN_TYPES = (
    "google.protobuf.Struct",
    "google.protobuf.Int64Value",
    "google.protobuf.DoubleValue",
    "google.protobuf.StringValue",
    "mapapi.v1.Counter",
    "mapapi.v1.Account",
)

MAP_TYPES = (
    "mapapi.v1.Mission",
    "mapapi.v1.Vertex",
    "mapapi.v1.Edge",
    "mapapi.v1.Landmark",
    "mapapi.v1.PointCloudBlock",
)
"""The types of the map tables `mapctl import` writes (`mapapi.maps.schema`)."""

TABLE_TYPES = BUILTIN_TYPES + MAP_TYPES
"""What `mapctl table create --type` accepts: types whose values every command can
show and every peer of any swarm knows. Other types of the protobuf pool (the
wire's own messages, `google.protobuf.Value`, ...) are no table types."""

_INT64_TYPES = (FieldDescriptor.CPPTYPE_INT64, FieldDescriptor.CPPTYPE_UINT64)
_FLOAT_TYPES = (FieldDescriptor.CPPTYPE_DOUBLE, FieldDescriptor.CPPTYPE_FLOAT)


def message_class(type_name: str) -> type[Message]:
    """The Python class of the protobuf message called `type_name`.

    Any message type imported into the default descriptor pool works; the
    built-ins (`BUILTIN_TYPES`) are always there.

    Raises:
        UsageError: no such message type is known.
    """
    from mapapi.core import codec

    codec.ensure_registered()
    try:
        descriptor = _default_pool().FindMessageTypeByName(type_name)
    except KeyError:
        raise UsageError(
            f"unknown message type {type_name!r}; built-in types: {', '.join(BUILTIN_TYPES)}"
        ) from None
    return message_factory.GetMessageClass(descriptor)


def check_new_table(name: str, type_name: str) -> None:
    """Refuse a table `table create` should not make: a name no other peer
    could replicate (`limits.table_name`), or a type that is no table type.

    Raises:
        UsageError: naming the limit, or listing the table types.
    """
    limits.table_name(name)
    if type_name not in TABLE_TYPES:
        raise UsageError(f"{type_name!r} is not a table type; use one of: {', '.join(TABLE_TYPES)}")


@dataclass(frozen=True)
class TableDescriptor:
    """A named collection of items of one protobuf message type.

    Attributes:
        name: the table's name, unique in a repository.
        message_type: the payload class; `google.protobuf.Struct` holds schemaless JSON.

    Where an item lies in space depends on its type alone (`mapapi.lookup.extent`).
    """

    name: str
    message_type: type[Message]

    @classmethod
    def named(cls, name: str, type_name: str) -> TableDescriptor:
        """A descriptor for `name` whose type is looked up by its full protobuf name."""
        return cls(name, message_class(type_name))

    @property
    def type_name(self) -> str:
        """The full protobuf name of the payload type."""
        return str(self.message_type.DESCRIPTOR.full_name)

    def encode(self, message: Message) -> bytes:
        """Serialize a payload; refuses a message of another type, or one larger
        than `limits.MAX_PAYLOAD_BYTES` (LimitExceeded)."""
        if not isinstance(message, self.message_type):
            raise UsageError(
                f"table {self.name!r} holds {self.type_name}, "
                f"not {type(message).DESCRIPTOR.full_name}"
            )
        data = bytes(message.SerializeToString(deterministic=True))
        limits.payload(len(data))
        return data

    def decode(self, data: bytes) -> Message:
        """Parse a stored payload.

        Raises:
            CorruptPayload: the bytes are no message of the table's type (a
                damaged store); it carries them, so a caller that knows the
                store can name the file and the item (`CorruptPayload.at`).
        """
        message = self.message_type()
        try:
            message.ParseFromString(data)
        except DecodeError as exc:
            raise CorruptPayload(self.name, self.type_name, data, str(exc)) from exc
        return message

    def from_json(self, text: str) -> Message:
        """Parse JSON text (protobuf JSON mapping) into a payload.

        JSON numbers must be finite: NaN and +-Infinity (which Python's JSON
        reader accepts) only fit a `double` or `float` field of a typed
        message, which stores them as IEEE values and shows them as protobuf's
        JSON does ("NaN", "Infinity", "-Infinity"). A schemaless number (in a
        Struct, Value or ListValue) has no such form: stored, it could never be
        written out as JSON again.

        Raises:
            UsageError: the text is not JSON, does not fit the type, or holds a
                non-finite number where the type has no place for one (the
                message names the field).
        """
        message = self.message_type()
        try:
            json_format.Parse(text, message)
        except json_format.ParseError as exc:
            raise UsageError(
                f"data does not fit table {self.name!r} ({self.type_name}): {exc}"
            ) from exc
        for path, value in _schemaless_non_finite(message, ""):
            raise UsageError(
                f"data does not fit table {self.name!r} ({self.type_name}): {path or 'the value'} "
                f"is {_non_finite_text(value.number_value)}; JSON numbers must be "  # type: ignore[attr-defined]
                "finite (only a double or float field of a typed table holds NaN or Infinity)"
            )
        return message

    def to_dict(self, message: Message) -> Any:
        """The payload as plain JSON for scripts (`plain_json`)."""
        return plain_json(message)

    def data_to_dict(self, data: bytes) -> Any:
        """`to_dict` of a stored payload."""
        return self.to_dict(self.decode(data))

    def field_value(self, message: Message, name: str) -> Any:
        """The value of top-level field `name` in its plain JSON form (None when absent).

        Unset proto3 scalars read as their defaults (0, "", false) and 64-bit
        integers as numbers, so a search for `value == 0` or `value == 5` finds
        what the user means.
        """
        value = plain_json(message)
        return value.get(name) if isinstance(value, dict) else None

    def field_json(self, message: Message, name: str) -> str:
        """`field_value` as canonical JSON text (see `canonical_json`)."""
        return self.canonical_json(self.field_value(message, name))

    @staticmethod
    def canonical_json(value: Any) -> str:
        """JSON text that equal JSON values share: keys sorted, integral numbers
        written as integers (JSON has one number type; Struct stores doubles)."""
        return json.dumps(_integral_as_int(value), sort_keys=True)


def plain_json(message: Message) -> Any:
    """A message as plain JSON for scripts, not protobuf's canonical JSON mapping.

    The canonical mapping writes 64-bit integers as strings and leaves out fields
    at their default; a script reading `--json` wants numbers and every field.
    So: fields keep their proto names and declaration order, defaults are
    present (an unset message field is null), 64-bit integers
    (and Int64Value/UInt64Value) are numbers, and a Struct's integral numbers are
    integers (it stores doubles, so `{"n": 1}` would come back as 1.0). Struct
    maps come out with sorted keys, so output is stable across runs. Other
    well-known types (Timestamp, Duration, ...) keep their canonical JSON form.
    """
    if next(_schemaless_non_finite(message, ""), None) is not None:
        # Stored before `from_json` refused them (or sent by another peer): the
        # same strings protobuf's JSON writes for a non-finite double.
        message = _finite_copy(message)
    value = json_format.MessageToDict(
        message, preserving_proto_field_name=True, always_print_fields_with_no_presence=True
    )
    return _plain(message.DESCRIPTOR, value)


def _non_finite_text(number: float) -> str:
    """How protobuf's JSON mapping writes a non-finite double."""
    return "NaN" if math.isnan(number) else ("Infinity" if number > 0 else "-Infinity")


def _schemaless_non_finite(message: Message, path: str) -> Iterator[tuple[str, Message]]:
    """Each `google.protobuf.Value` in `message` (a Struct's, a ListValue's, or
    any field's) holding a non-finite number, with its path (`pose.y[1]`).
    Typed double and float fields are not schemaless: they do not count."""
    name = message.DESCRIPTOR.full_name
    if name == "google.protobuf.Value":
        kind = message.WhichOneof("kind")
        if kind == "number_value" and not math.isfinite(message.number_value):  # type: ignore[attr-defined]
            yield path, message
        elif kind in ("struct_value", "list_value"):
            yield from _schemaless_non_finite(getattr(message, kind), path)
        return
    if name == "google.protobuf.Struct":
        fields = message.fields  # type: ignore[attr-defined]
        for key in sorted(fields):
            yield from _schemaless_non_finite(fields[key], f"{path}.{key}" if path else key)
        return
    if name == "google.protobuf.ListValue":
        for i, value in enumerate(message.values):  # type: ignore[attr-defined]
            yield from _schemaless_non_finite(value, f"{path}[{i}]")
        return
    for field, value in message.ListFields():
        if field.message_type is None:
            continue
        where = f"{path}.{field.name}" if path else field.name
        if field.message_type.GetOptions().map_entry:
            children = [(f"{where}.{k}", v) for k, v in value.items()]
        elif field.is_repeated:
            children = [(f"{where}[{i}]", v) for i, v in enumerate(value)]
        else:
            children = [(where, value)]
        for child_path, child in children:
            if isinstance(child, Message):
                yield from _schemaless_non_finite(child, child_path)


def _finite_copy(message: Message) -> Message:
    """A copy of `message` whose schemaless non-finite numbers are their JSON strings."""
    copy = type(message)()
    copy.CopyFrom(message)
    for _, value in list(_schemaless_non_finite(copy, "")):
        value.string_value = _non_finite_text(value.number_value)  # type: ignore[attr-defined]
    return copy


_INT_WRAPPERS = ("google.protobuf.Int64Value", "google.protobuf.UInt64Value")
_JSON_VALUES = ("google.protobuf.Struct", "google.protobuf.Value", "google.protobuf.ListValue")


def _plain(descriptor: Descriptor, value: Any) -> Any:
    """`value` (canonical JSON of a `descriptor` message) with numbers made plain."""
    name = descriptor.full_name
    if name in _INT_WRAPPERS:
        return int(value)
    if name in _JSON_VALUES:
        return json.loads(json.dumps(_integral_as_int(value), sort_keys=True))
    if not isinstance(value, dict) or name == "google.protobuf.Any":
        return value  # a well-known type written as a string, or an Any: as is
    # Every field, in declaration order; an unset message field (or unset
    # `optional` scalar) is null, which `from_json` reads back as unset.
    return {
        f.name: None if value.get(f.name) is None else _plain_field(f, value[f.name])
        for f in descriptor.fields
    }


def _plain_field(field: FieldDescriptor, value: Any) -> Any:
    entry = field.message_type
    if entry is not None and entry.GetOptions().map_entry:
        # Map keys stay strings (JSON object keys are), values are made plain.
        element = entry.fields_by_name["value"]
        return {k: _plain_scalar(element, v) for k, v in value.items()}
    if field.is_repeated:
        return [_plain_scalar(field, v) for v in value]
    return _plain_scalar(field, value)


def _plain_scalar(field: FieldDescriptor, value: Any) -> Any:
    if field.message_type is not None:
        return _plain(field.message_type, value)
    if field.cpp_type in _INT64_TYPES:
        return int(value)
    return value


def _integral_as_int(value: Any) -> Any:
    if isinstance(value, float) and value.is_integer():
        return int(value)
    if isinstance(value, dict):
        return {k: _integral_as_int(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_integral_as_int(v) for v in value]
    return value
