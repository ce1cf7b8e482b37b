"""Values and names that must not poison a repository (issue 18, parts 4 and 7).

A NaN or an infinity in JSON used to commit and then break every command that
showed it; a table name of 2,000 characters was accepted but its chunk could
never be replicated; `--type` took any type of the protobuf pool.
"""

from __future__ import annotations

import math
import sqlite3
from pathlib import Path

import pytest
from google.protobuf import struct_pb2

from mapapi.core.limits import MAX_TEXT
from mapapi.core.table import TABLE_TYPES
from tests.cli.conftest import STRUCT, Mapctl

NON_FINITE = ["NaN", "Infinity", "-Infinity"]


def _one_line_error(outcome_err: str) -> str:
    lines = [line for line in outcome_err.splitlines() if line.strip()]
    assert len(lines) == 1, outcome_err
    assert "internal error" not in lines[0]
    assert "Traceback" not in outcome_err
    return lines[0]


class TestNonFiniteNumbers:
    @pytest.mark.parametrize("token", NON_FINITE)
    def test_a_struct_refuses_them_naming_the_field(self, points: Mapctl, token: str) -> None:
        done = points.main("set", "pts", f'{{"pose": {{"x": 1, "y": [0, {token}]}}}}')
        assert done.code == 2
        line = _one_line_error(done.err)
        assert "pose.y[1]" in line, line
        assert token in line
        assert points.json("diff")["changes"] == []  # nothing was staged

    @pytest.mark.parametrize("token", NON_FINITE)
    def test_a_double_field_of_a_typed_table_keeps_them(self, mapctl: Mapctl, token: str) -> None:
        mapctl("table", "create", "levels", "--type", "google.protobuf.DoubleValue")
        mapctl("chunk", "create", "levels")
        item = mapctl.insert(token, table="levels")  # quoted, as protobuf's JSON wants
        mapctl.commit("levels")
        # Shown as protobuf's JSON mapping shows them: the strings "NaN", "Infinity", ...
        (row,) = mapctl.json("ls", "levels")["items"]
        assert row == {"id": item, "data": token}
        assert mapctl.json("get", "levels", item) == token
        assert token in mapctl("ls", "levels")

    def test_an_integer_field_refuses_them(self, mapctl: Mapctl) -> None:
        mapctl("table", "create", "hits", "--type", "mapapi.v1.Counter")
        mapctl("chunk", "create", "hits")
        done = mapctl.main("set", "hits", '{"name": "a", "value": NaN}')
        assert done.code == 2
        assert "value" in _one_line_error(done.err)


def _poison(repo: Path, item: str) -> None:
    """Overwrite every stored revision of `item` with a Struct holding NaN, as a
    store written before the check (or by a hostile peer) may hold."""
    poisoned = struct_pb2.Struct()
    poisoned.update({"x": math.nan, "y": math.inf, "z": -math.inf, "ok": 1})
    data = poisoned.SerializeToString(deterministic=True)
    with sqlite3.connect(repo / ".mapapi" / "store.sqlite") as con:
        changed = con.execute(
            "UPDATE revisions SET data = ? WHERE item_id = ?", (data, bytes.fromhex(item))
        )
        assert changed.rowcount >= 1


class TestAPoisonedStoreCanBeShown:
    def test_every_reading_command_shows_the_stored_values(self, points: Mapctl) -> None:
        item = points.insert({"x": 1})
        first = points.commit("first")
        _poison(points.repo, item)
        expected = {"ok": 1, "x": "NaN", "y": "Infinity", "z": "-Infinity"}
        assert points.json("ls", "pts")["items"] == [{"id": item, "data": expected}]
        assert points.json("ls", "pts", "--at", str(first["time"]))["items"][0]["data"] == expected
        assert points.json("get", "pts", item) == expected
        assert points.json("show", first["commit"])["changes"][0]["data"] == expected
        assert points.json("log", "pts", item)[0]["data"] == expected
        for args in (("ls", "pts"), ("show", first["commit"]), ("log", "pts", item)):
            assert "NaN" in points(*args)
        # A staged change over the poisoned base, then the removal of the item.
        points("set", "pts", item, '{"x": 2}')
        assert points.json("diff")["changes"][0]["base"] == expected
        assert "NaN" in points("diff")
        points("rm", "pts", item)
        removed = points.commit("removed")
        assert points.json("ls", "pts")["items"] == []
        assert points.json("show", removed["commit"])["changes"][0]["op"] == "removed"
        assert [r["data"] for r in points.json("log", "pts", item)] == [None, expected]


class TestTableNames:
    def test_a_name_longer_than_the_wire_carries_is_refused(self, mapctl: Mapctl) -> None:
        limit = MAX_TEXT["table"]
        done = mapctl.main("table", "create", "a" * 2000, "--type", STRUCT)
        assert done.code == 2
        line = _one_line_error(done.err)
        assert str(limit) in line, line
        assert "MAX_TEXT['table']" in line
        assert mapctl.json("table", "list")["tables"] == []

    def test_the_longest_name_that_travels_is_accepted(self, mapctl: Mapctl) -> None:
        name = "a" * MAX_TEXT["table"]
        mapctl("table", "create", name, "--type", STRUCT)
        assert [t["name"] for t in mapctl.json("table", "list")["tables"]] == [name]


class TestTableTypes:
    @pytest.mark.parametrize(
        "type_name", ["google.protobuf.Value", "google.protobuf.Timestamp", "mapapi.v1.Revision"]
    )
    def test_a_type_that_is_no_table_type_is_refused(self, mapctl: Mapctl, type_name: str) -> None:
        done = mapctl.main("table", "create", "t", "--type", type_name)
        assert done.code == 2
        line = _one_line_error(done.err)
        assert type_name in line, line
        assert all(t in line for t in TABLE_TYPES)
        assert mapctl.json("table", "list")["tables"] == []

    @pytest.mark.parametrize("type_name", TABLE_TYPES)
    def test_every_table_type_is_accepted(self, mapctl: Mapctl, type_name: str) -> None:
        mapctl("table", "create", "t", "--type", type_name)
        assert mapctl.json("table", "list")["tables"][0]["type"] == type_name
