"""Generic conversion between body dataclasses and their protobuf messages.

A body dataclass mirrors its wire message field by field (same names). Ids
travel as 16 bytes (empty for None); `Revision` and `CommitRecord` use the
storage codec, and an optional one (`X | None`) is an unset field when None;
nested dataclasses (`Member`, `TableInfo`) and tuples of any of these recurse.
Anything malformed on the way in raises ValueError, which the envelope decoder
turns into ProtocolError; so does a field over its limit in
`mapapi.core.limits` (`LimitExceeded` is a ValueError), checked on the protobuf
message before any dataclass is built from it.
"""

from __future__ import annotations

import dataclasses
import types
import typing
from typing import Any

from mapapi.core import codec as storage
from mapapi.core import limits
from mapapi.core.history import CommitRecord, Revision
from mapapi.core.ids import Id

_SCALARS = (str, int, float, bool, bytes)


_HINTS: dict[type, dict[str, Any]] = {}


def _hints(cls: type) -> dict[str, Any]:
    hints = _HINTS.get(cls)
    if hints is None:
        hints = _HINTS[cls] = typing.get_type_hints(cls)
    return hints


def _optional(hint: Any) -> tuple[Any, bool]:
    """(inner type, whether None is allowed) of `X | None`."""
    if isinstance(hint, types.UnionType) or typing.get_origin(hint) is typing.Union:
        args = [a for a in typing.get_args(hint) if a is not type(None)]
        return args[0], True
    return hint, False


def fill(body: Any, message: Any) -> None:
    """Copy the dataclass `body` into the (mutable) protobuf `message`."""
    message.SetInParent()  # an empty body must still select its oneof field
    for name, hint in _hints(type(body)).items():
        value = getattr(body, name)
        kind, nullable = _optional(hint)
        if value is None and nullable and not (isinstance(kind, type) and issubclass(kind, Id)):
            continue  # an optional message stays unset
        if typing.get_origin(kind) is tuple:
            (element,) = [a for a in typing.get_args(kind) if a is not Ellipsis]
            repeated = getattr(message, name)
            for item in value:
                _put_element(repeated, element, item)
        elif isinstance(kind, type) and issubclass(kind, Id):
            setattr(message, name, value.to_bytes() if value is not None else b"")
        elif kind in _SCALARS:
            setattr(message, name, value)
        elif kind is Revision or kind is CommitRecord:
            getattr(message, name).CopyFrom(_to_pb(kind, value))
        else:
            fill(value, getattr(message, name))


def _put_element(repeated: Any, element: type, value: Any) -> None:
    if element is Revision or element is CommitRecord:
        repeated.append(_to_pb(element, value))
    elif dataclasses.is_dataclass(element):
        fill(value, repeated.add())
    elif issubclass(element, Id):
        repeated.append(value.to_bytes())
    else:
        repeated.append(value)


def _to_pb(kind: type, value: Any) -> Any:
    if kind is Revision:
        return storage.revision_to_pb(value)
    return storage.commit_record_to_pb(value)


def read(cls: type, message: Any) -> Any:
    """The dataclass `cls` read back from its protobuf `message`.

    Raises:
        ValueError: an id has the wrong length or a nested value is invalid.
        LimitExceeded: a field exceeds its limit (a ValueError too).
    """
    values: dict[str, Any] = {}
    for name, hint in _hints(cls).items():
        kind, nullable = _optional(hint)
        raw = getattr(message, name)
        if typing.get_origin(kind) is tuple:
            (element,) = [a for a in typing.get_args(kind) if a is not Ellipsis]
            limits.count(name, len(raw))
            if element is str or element is bytes:
                for item in raw:
                    limits.field(name, item)
            values[name] = tuple(_read_value(element, item) for item in raw)
        elif isinstance(kind, type) and issubclass(kind, Id):
            values[name] = None if nullable and not raw else kind.from_bytes(raw)
        elif nullable and not message.HasField(name):
            values[name] = None
        else:
            if isinstance(raw, str | bytes):
                limits.field(name, raw)
            values[name] = _read_value(kind, raw)
    return cls(**values)


def _read_value(kind: type, raw: Any) -> Any:
    if kind is Revision:
        limits.size("data", raw.data)
        limits.size("table", raw.table)
        limits.lamport("revision insert time", raw.insert_time)
        limits.lamport("revision update time", raw.update_time)
        return storage.revision_from_pb(raw)
    if kind is CommitRecord:
        limits.count("chunks", len(raw.chunks))
        limits.size("message", raw.message)
        limits.lamport("commit time", raw.time)
        return storage.commit_record_from_pb(raw)
    if dataclasses.is_dataclass(kind):
        return read(kind, raw)
    if issubclass(kind, Id):
        return kind.from_bytes(raw)
    if kind in _SCALARS:
        return raw
    raise TypeError(f"no wire form for {kind!r}")
