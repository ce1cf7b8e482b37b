"""A control call's JSON answer, written in parts (issue 14 §1).

`json.dumps` is one C call that keeps the interpreter lock until it is done: for
`ls` of 50,000 rows that is a long while in which the daemon's event loop, even
if the call runs in a worker thread, cannot run. `dumps` writes each element of
a long list with its own call and joins the text, which is the same text
`json.dumps` writes (its default separators), so the lock changes hands between
parts.
"""

from __future__ import annotations

import json
from typing import Any

PART = 200
"""Elements of a list from which they are written one call each."""


def dumps(value: Any) -> str:
    """`json.dumps(value)`, with long lists (also as a dict's values) written element
    by element."""
    if isinstance(value, dict) and all(isinstance(k, str) for k in value):
        return "{" + ", ".join(f"{json.dumps(k)}: {dumps(v)}" for k, v in value.items()) + "}"
    if isinstance(value, list) and len(value) >= PART:
        return "[" + ", ".join(json.dumps(v) for v in value) + "]"  # each small, in C
    return json.dumps(value)
