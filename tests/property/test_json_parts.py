"""A control answer written in parts (service/json_parts.py) is the text `json.dumps`
writes, whatever the value and however small the parts."""

from __future__ import annotations

import json

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mapapi.service import json_parts

scalars = st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=8)
values = st.recursive(
    scalars,
    lambda inner: st.lists(inner, max_size=6) | st.dictionaries(st.text(max_size=5), inner),
    max_leaves=40,
)


@settings(max_examples=200, deadline=None)
@given(values, st.integers(0, 4))
def test_the_parts_are_the_text_of_json_dumps(value: object, part: int) -> None:
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(json_parts, "PART", part)  # 0: every list in parts
        assert json_parts.dumps(value) == json.dumps(value)


def test_an_ls_answer_of_many_rows_round_trips() -> None:
    rows = [{"id": f"{i:032x}", "data": {"x": i / 3, "name": f"p{i}"}} for i in range(1000)]
    answer = {"time": 7, "items": rows}
    assert json.loads(json_parts.dumps(answer)) == answer
