"""`log`, `show` and short id prefixes."""

from __future__ import annotations

import asyncio
import sqlite3
from pathlib import Path
from typing import Any

from google.protobuf import struct_pb2

from mapapi import ItemId, Peer, UsageError
from tests.cli.conftest import Mapctl


def _commit_with_ids(repo: Path, *item_ids: str) -> None:
    """Commit items with chosen ids through the library (ids are random in the CLI)."""

    async def run() -> None:
        async with Peer.open(repo) as peer:
            (chunk,) = peer.chunks("pts")
            tx = peer.begin()
            for item_id in item_ids:
                value = struct_pb2.Struct()
                value.update({"id": item_id})
                tx.insert("pts", value, chunk.id, ItemId(item_id))
            await tx.commit("chosen ids")

    asyncio.run(run())


def _records(log: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Log rows as `commit --json` prints the same commits (no `seq`: a position
    in the log, not part of the commit)."""
    return [{k: v for k, v in row.items() if k != "seq"} for row in log]


class TestLog:
    def test_log_json_lists_commits_newest_first(self, points: Mapctl) -> None:
        assert points.json("log") == []
        item = points.insert({"v": 1})
        first = points.commit("first")
        points("set", "pts", item, '{"v": 2}')
        second = points.commit("second")
        log = points.json("log")
        assert _records(log) == [second, first]
        assert [c["time"] for c in log] == [2, 1]
        assert set(log[0]) == {
            *("seq", "commit", "time", "author", "author_name", "view", "message", "chunks")
        }
        assert log[0]["chunks"] == [points.json("chunk", "list")["chunks"][0]["id"]]
        assert _records(points.json("log", "-n", "1")) == [second]

    def test_log_of_a_table(self, points: Mapctl) -> None:
        points("table", "create", "other", "--type", "google.protobuf.Struct")
        points("chunk", "create", "other")
        points.insert({"v": 1})
        ours = points.commit("pts")
        points.insert({"v": 1}, table="other")
        theirs = points.commit("other")
        assert _records(points.json("log", "pts")) == [ours]
        assert _records(points.json("log", "other")) == [theirs]

    def test_log_plain(self, points: Mapctl) -> None:
        points.insert({"v": 1})
        record = points.commit("hello log")
        out = points("log")
        assert record["commit"][:8] in out
        assert "hello log" in out

    def test_item_revisions_newest_first_with_data(self, points: Mapctl) -> None:
        item = points.insert({"v": 1})
        first = points.commit("insert")
        points("set", "pts", item, '{"v": 2}')
        second = points.commit("update")
        points("rm", "pts", item)
        third = points.commit("remove")
        revisions = points.json("log", "pts", item[:5])
        assert revisions == [
            {**third, "seq": 3, "data": None},
            {**second, "seq": 2, "data": {"v": 2.0}},
            {**first, "seq": 1, "data": {"v": 1.0}},
        ]
        assert points.json("log", "pts", item, "-n", "1") == revisions[:1]
        assert "update" in points("log", "pts", item)

    def test_item_revisions_of_an_unknown_table(self, points: Mapctl) -> None:
        item = points.insert({"v": 1})
        points.commit()
        result = points.invoke("log", "nope", item)
        assert isinstance(result.exception, UsageError)


class TestShow:
    def test_show_json_with_its_changes(self, points: Mapctl) -> None:
        kept = points.insert({"v": 1})
        gone = points.insert({"v": 2})
        points.commit("seed")
        points("set", "pts", kept, '{"v": 3}')
        points("rm", "pts", gone)
        added = points.insert({"v": 4})
        record = points.commit("mixed")
        shown = points.json("show", record["commit"])
        assert {k: v for k, v in shown.items() if k not in ("changes", "seq")} == record
        assert sorted(shown["changes"], key=lambda c: c["op"]) == [
            {"table": "pts", "id": added, "op": "inserted", "data": {"v": 4.0}},
            {"table": "pts", "id": gone, "op": "removed", "data": None},
            {"table": "pts", "id": kept, "op": "updated", "data": {"v": 3.0}},
        ]

    def test_show_plain(self, points: Mapctl) -> None:
        points.insert({"v": 1})
        record = points.commit("visible message")
        out = points("show", record["commit"])
        assert f"commit {record['commit']}" in out
        assert "visible message" in out
        assert "inserted" in out

    def test_show_by_prefix(self, points: Mapctl) -> None:
        points.insert({"v": 1})
        record = points.commit("short")
        assert points.json("show", record["commit"][:4])["commit"] == record["commit"]
        assert points.json("show", record["commit"][:7].upper())["commit"] == record["commit"]

    def test_show_unknown_commit(self, points: Mapctl) -> None:
        outcome = points.main("show", "0" * 32)
        assert outcome.code == 2
        assert outcome.err_lines == [f"error: no commit {'0' * 32}; `mapctl log` lists the commits"]


class TestPrefixes:
    def test_get_by_prefix(self, points: Mapctl) -> None:
        item = points.insert({"v": 1})
        points.commit()
        assert points.json("get", "pts", item[:4]) == {"v": 1.0}
        assert points.json("get", "pts", item[:10].upper()) == {"v": 1.0}

    def test_ambiguous_prefix_exits_2(self, points: Mapctl) -> None:
        a, b = "abcd" + "0" * 28, "abcd" + "1" * 28
        _commit_with_ids(points.repo, a, b)
        assert points.json("get", "pts", "abcd0") == {"id": a}
        outcome = points.main("get", "pts", "abcd")
        assert outcome.code == 2
        assert outcome.err_lines == ["error: item id prefix 'abcd' is ambiguous; give more digits"]

    def test_too_short_prefix_exits_2(self, points: Mapctl) -> None:
        item = points.insert({"v": 1})
        record = points.commit()
        for args in (["get", "pts", item[:3]], ["show", record["commit"][:3]]):
            outcome = points.main(*args)
            assert outcome.code == 2
            assert len(outcome.err_lines) == 1
            assert "prefix of 4 or more" in outcome.err

    def test_unknown_prefix_and_bad_hex(self, points: Mapctl) -> None:
        assert "no item id starts with 'ffff'" in str(points.invoke("get", "pts", "ffff").exception)
        for bad in ("zzzz", "z" * 32):
            result = points.invoke("get", "pts", bad)
            assert isinstance(result.exception, UsageError), result.exception


class TestLogNamesAndOrder:
    """`log` names authors and numbers commits 1..n (issue 15)."""

    def test_authors_by_name_ids_in_json_and_with_v(self, points: Mapctl) -> None:
        points.insert({"v": 1})
        points.commit("first")
        points.insert({"v": 2})
        points.commit("second")
        log = points.json("log")
        assert [c["seq"] for c in log] == [2, 1]
        assert {c["author_name"] for c in log} == {"bench"}
        assert len(log[0]["author"]) == 32
        plain = points("log")
        assert "bench" in plain
        assert log[0]["author"][:8] not in plain
        assert log[0]["author"][:8] in points("-v", "log")

    def test_seq_counts_the_whole_log_under_a_filter(self, points: Mapctl) -> None:
        for v in range(3):
            points.insert({"v": v})
            points.commit(str(v))
        assert [c["seq"] for c in points.json("log", "-n", "1")] == [3]
        assert points.json("show", points.json("log")[-1]["commit"])["seq"] == 1

    def test_a_named_view_shows_in_the_author(self, points: Mapctl) -> None:
        points.insert({"v": 1}, view="bob")
        points.commit("from bob", view="bob")
        assert points.json("log")[0]["view"] == "bob"
        assert "bench/bob" in points("log")

    def test_an_old_store_falls_back_to_the_configured_name(self, points: Mapctl) -> None:
        points.insert({"v": 1})
        points.commit("before names were kept")
        store = points.repo / ".mapapi" / "store.sqlite"
        with sqlite3.connect(store) as con:  # as a store of the first format was
            con.execute("ALTER TABLE commits DROP COLUMN author_name")
            con.execute("ALTER TABLE commits DROP COLUMN view")
        (row,) = points.json("log")
        assert (row["author_name"], row["view"]) == ("bench", "")
        assert "bench" in points("log")
