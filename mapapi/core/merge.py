"""Auto-merge policies for update/update conflicts (DESIGN §5, step 5).

A policy takes (base, ours, theirs) payloads and returns the merged payload,
or None when it cannot merge; the peer tries a table's policy before it
reports a conflict.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from google.protobuf import json_format
from google.protobuf.message import Message

MergePolicy = Callable[[Message | None, Message, Message], Message | None]


def _json(message: Message) -> Any:
    return json_format.MessageToDict(message, preserving_proto_field_name=True)


def _fields(message: Message | None) -> dict[str, Any]:
    if message is None:
        return {}
    value = _json(message)
    return value if isinstance(value, dict) else {}


def disjoint_fields(base: Message | None, ours: Message, theirs: Message) -> Message | None:
    """Merge when the two sides changed different top-level fields.

    Their version wins for the fields they changed, ours for the fields we
    changed; if both changed the same field (even to equal values) it is a
    conflict, as in the original Map API.
    """
    if base is None:
        return None
    if not all(isinstance(_json(m), dict) for m in (base, ours, theirs)):
        # A payload whose JSON is not an object (a wrapper such as Int64Value)
        # is one field: it merges only when one side left it unchanged.
        return ours if theirs == base else theirs if ours == base else None
    b, o, t = _fields(base), _fields(ours), _fields(theirs)
    keys = set(b) | set(o) | set(t)
    ours_changed = {k for k in keys if o.get(k) != b.get(k)}
    theirs_changed = {k for k in keys if t.get(k) != b.get(k)}
    if ours_changed & theirs_changed:
        return None
    merged = dict(t)
    for key in ours_changed:
        if key in o:
            merged[key] = o[key]
        else:
            merged.pop(key, None)
    result = type(ours)()
    json_format.ParseDict(merged, result)
    return result
