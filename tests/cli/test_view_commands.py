"""Views and staging: `view open/list/abort`, `status`, `set`, `get`, `ls`, `rm`."""

from __future__ import annotations

import json
from pathlib import Path

from mapapi import ItemNotFound, UsageError, ViewClosedError
from tests.cli.conftest import Mapctl


class TestSet:
    def test_insert_with_json_text_prints_the_id(self, points: Mapctl) -> None:
        item = points("set", "pts", '{"x": 1, "name": "dock"}').strip()
        assert len(item) == 32
        assert points.json("get", "pts", item) == {"name": "dock", "x": 1.0}

    def test_insert_json_output(self, points: Mapctl) -> None:
        out = points.json("set", "pts", '{"x": 1}')
        assert out["op"] == "insert"
        assert len(out["id"]) == 32

    def test_update_with_json_text(self, points: Mapctl) -> None:
        item = points.insert({"x": 1})
        points.commit()
        out = points.json("set", "pts", item, '{"x": 2}')
        assert out == {"id": item, "op": "update"}
        assert points.json("get", "pts", item) == {"x": 2.0}

    def test_update_of_a_staged_insert(self, points: Mapctl) -> None:
        item = points.insert({"x": 1})
        points("set", "pts", item, '{"x": 5}')
        assert points.json("get", "pts", item) == {"x": 5.0}
        assert [s["op"] for s in points.json("status")["staged"]] == ["insert"]

    def test_data_from_file(self, points: Mapctl, tmp_path: Path) -> None:
        source = tmp_path / "item.json"
        source.write_text(json.dumps({"kind": "wall", "h": 2.5}))
        item = points.json("set", "pts", f"@{source}")["id"]
        source.write_text(json.dumps({"kind": "door"}))
        points("set", "pts", item, f"@{source}")
        assert points.json("get", "pts", item) == {"kind": "door"}

    def test_missing_file_is_a_usage_error(self, points: Mapctl, tmp_path: Path) -> None:
        result = points.invoke("set", "pts", f"@{tmp_path / 'absent.json'}")
        assert result.exit_code == 2
        assert "cannot read" in result.output

    def test_data_from_stdin(self, points: Mapctl) -> None:
        item = points.json("set", "pts", "-", input='{"from": "stdin"}\n')["id"]
        assert points.json("get", "pts", item) == {"from": "stdin"}
        points("set", "pts", item, "-", input='{"from": "stdin again"}')
        assert points.json("get", "pts", item) == {"from": "stdin again"}

    def test_bad_json_is_a_usage_error(self, points: Mapctl) -> None:
        result = points.invoke("set", "pts", "{not json")
        assert isinstance(result.exception, UsageError)
        assert "does not fit table 'pts'" in str(result.exception)

    def test_too_many_arguments(self, points: Mapctl) -> None:
        result = points.invoke("set", "pts", "a", "b", "c")
        assert result.exit_code == 2
        assert "quote DATA" in result.output

    def test_update_of_unknown_item(self, points: Mapctl) -> None:
        result = points.invoke("set", "pts", "0" * 32, '{"x": 1}')
        assert isinstance(result.exception, ItemNotFound)


class TestSetChunk:
    def test_one_chunk_is_the_default(self, points: Mapctl) -> None:
        (chunk,) = points.json("chunk", "list")["chunks"]
        points.insert({"x": 1})
        assert points.json("status")["staged"][0]["chunk"] == chunk["id"]

    def test_no_chunk_is_an_error(self, mapctl: Mapctl) -> None:
        mapctl("table", "create", "empty", "--type", "google.protobuf.Struct")
        result = mapctl.invoke("set", "empty", '{"x": 1}')
        assert isinstance(result.exception, UsageError)
        assert "mapctl chunk create empty" in str(result.exception)

    def test_two_chunks_need_chunk(self, points: Mapctl) -> None:
        second = points.json("chunk", "create", "pts")["id"]
        result = points.invoke("set", "pts", '{"x": 1}')
        assert isinstance(result.exception, UsageError)
        assert "--chunk" in str(result.exception)
        item = points.json("set", "pts", "--chunk", second[:6], '{"x": 1}')["id"]
        assert points.json("status")["staged"] == [
            {"op": "insert", "table": "pts", "id": item, "chunk": second}
        ]

    def test_chunk_with_an_update_is_refused(self, points: Mapctl) -> None:
        (chunk,) = points.json("chunk", "list")["chunks"]
        item = points.insert({"x": 1})
        points.commit()
        result = points.invoke("set", "pts", item, "--chunk", chunk["id"], '{"x": 2}')
        assert isinstance(result.exception, UsageError)
        assert "inserts" in str(result.exception)


class TestGetLsRm:
    def test_get_json_is_the_fields_object(self, points: Mapctl) -> None:
        item = points.insert({"pose": {"x": 1, "y": 2}, "tags": ["a", "b"], "ok": True})
        points.commit()
        assert points.json("get", "pts", item) == {
            "ok": True,
            "pose": {"x": 1.0, "y": 2.0},
            "tags": ["a", "b"],
        }

    def test_get_plain_prints_the_fields(self, points: Mapctl) -> None:
        item = points.insert({"label": "charger"})
        assert "charger" in points("get", "pts", item)

    def test_get_at_a_past_time(self, points: Mapctl) -> None:
        item = points.insert({"v": 1})
        first = points.commit()["time"]
        points("set", "pts", item, '{"v": 2}')
        second = points.commit()["time"]
        assert second > first
        assert points.json("get", "pts", item, "--at", str(first)) == {"v": 1.0}
        assert points.json("get", "pts", item, "--at", str(second)) == {"v": 2.0}
        assert points.json("get", "pts", item) == {"v": 2.0}
        before = points.invoke("get", "pts", item, "--at", "0")
        assert isinstance(before.exception, ItemNotFound)

    def test_get_at_a_future_time_is_refused(self, points: Mapctl) -> None:
        item = points.insert({"v": 1})
        time = points.commit()["time"]
        result = points.invoke("get", "pts", item, "--at", str(time + 5))
        assert isinstance(result.exception, UsageError)
        assert "outside" in str(result.exception)

    def test_get_at_ignores_the_view(self, points: Mapctl) -> None:
        item = points.insert({"v": 1})
        time = points.commit()["time"]
        points("set", "pts", item, '{"v": 9}')
        assert points.json("get", "pts", item) == {"v": 9.0}
        assert points.json("get", "pts", item, "--at", str(time)) == {"v": 1.0}

    def test_ls_json(self, points: Mapctl) -> None:
        a = points.insert({"n": 1})
        b = points.insert({"n": 2})
        points.commit()
        c = points.insert({"n": 3})
        listing = points.json("ls", "pts")
        expected = {a: {"n": 1.0}, b: {"n": 2.0}, c: {"n": 3.0}}
        assert listing == {"items": [{"id": i, "data": expected[i]} for i in sorted(expected)]}
        other = points.json("ls", "pts", view="other")  # a fresh view sees only commits
        assert sorted(r["id"] for r in other["items"]) == sorted([a, b])

    def test_ls_by_chunk(self, points: Mapctl) -> None:
        (first,) = points.json("chunk", "list")["chunks"]
        second = points.json("chunk", "create", "pts")["id"]
        a = points.json("set", "pts", "--chunk", first["id"], '{"n": 1}')["id"]
        b = points.json("set", "pts", "--chunk", second, '{"n": 2}')["id"]
        assert [r["id"] for r in points.json("ls", "pts", "--chunk", first["id"])["items"]] == [a]
        assert [r["id"] for r in points.json("ls", "pts", "--chunk", second)["items"]] == [b]

    def test_ls_empty(self, points: Mapctl) -> None:
        assert points.json("ls", "pts") == {"items": []}
        assert "no items of pts" in points("ls", "pts")

    def test_rm_then_get_is_not_found(self, points: Mapctl) -> None:
        item = points.insert({"x": 1})
        points.commit()
        assert "staged removal" in points("rm", "pts", item[:8])
        result = points.main("get", "pts", item)
        assert result.code == 1
        assert result.err_lines == [
            f"error: no item {item} in table 'pts' at time 1; `mapctl ls pts` lists the items"
        ]
        points.commit()
        assert isinstance(points.invoke("get", "pts", item).exception, ItemNotFound)
        assert points.json("get", "pts", item, "--at", "1") == {"x": 1.0}
        assert points.json("ls", "pts") == {"items": []}

    def test_rm_of_a_staged_insert_unstages_it(self, points: Mapctl) -> None:
        item = points.insert({"x": 1})
        points("rm", "pts", item)
        assert points.json("status")["staged"] == []

    def test_get_from_the_wrong_table(self, points: Mapctl) -> None:
        points("table", "create", "other", "--type", "google.protobuf.Struct")
        item = points.insert({"x": 1})
        points.commit()
        result = points.invoke("get", "other", item)
        assert isinstance(result.exception, UsageError)
        assert "belongs to table 'pts'" in str(result.exception)


class TestViews:
    def test_status_of_a_closed_view(self, points: Mapctl) -> None:
        assert points.json("status") == {
            "view": "main",
            "open": False,
            "begin_time": None,
            "now": 0,
            "staged": [],
            "conflicts": [],
        }
        assert "not open" in points("status")

    def test_status_json_lists_staged_changes(self, points: Mapctl) -> None:
        kept = points.insert({"x": 1})
        gone = points.insert({"x": 2})
        points.commit()
        points("set", "pts", kept, '{"x": 3}')
        points("rm", "pts", gone)
        new = points.insert({"x": 4})
        status = points.json("status")
        assert status["open"] is True
        assert status["begin_time"] == 1
        assert status["now"] == 1
        assert [(s["op"], s["id"]) for s in status["staged"]] == [
            ("update", kept),
            ("remove", gone),
            ("insert", new),
        ]
        assert status["conflicts"] == []
        assert "staged changes" in points("status")

    def test_set_opens_the_view_and_commit_closes_it(self, points: Mapctl) -> None:
        assert points.json("view", "list") == {"views": []}
        points.insert({"x": 1})
        (view,) = points.json("view", "list")["views"]
        assert view == {
            "name": "main",
            "begin_time": 0,
            "isolation": "snapshot",
            "stale": False,
            "staged": 1,
            "conflicts": 0,
        }
        points.commit()
        assert points.json("view", "list") == {"views": []}

    def test_view_list_json_names_every_view(self, points: Mapctl) -> None:
        points("view", "open", view="zeta")
        points.insert({"x": 1}, view="alpha")
        points.insert({"x": 2}, view="alpha")
        views = points.json("view", "list")["views"]
        assert [(v["name"], v["staged"]) for v in views] == [("alpha", 2), ("zeta", 0)]
        assert "alpha" in points("view", "list")

    def test_open_json(self, points: Mapctl) -> None:
        opened = points.json("view", "open", "--serializable", view="s")
        assert opened == {
            "name": "s",
            "begin_time": 0,
            "isolation": "serializable",
            "stale": False,
            "staged": 0,
            "conflicts": 0,
        }

    def test_a_stale_view_reads_and_commits_offline_and_says_so(self, points: Mapctl) -> None:
        item = points.insert({"v": 1})
        time = points.commit()["time"]
        opened = points.json("view", "open", "--stale", view="here")
        assert opened["stale"] is True
        assert opened["begin_time"] == time
        assert opened["replicas"] == {"time": time, "leaders_silent_s": None}  # no swarm
        assert points.json("get", "pts", item, view="here") == {"v": 1.0}
        points("set", "pts", item, '{"v": 2}', view="here")
        assert points.json("commit", view="here")["time"] > time
        assert "in no swarm" in points("view", "open", "--stale", view="again")

    def test_a_stale_view_at_a_past_time_is_refused(self, points: Mapctl) -> None:
        result = points.invoke("view", "open", "--stale", "--at", "0")
        assert isinstance(result.exception, UsageError)
        assert "no --at" in str(result.exception)

    def test_open_at_a_past_time_reads_the_past(self, points: Mapctl) -> None:
        item = points.insert({"v": 1})
        first = points.commit()["time"]
        points("set", "pts", item, '{"v": 2}')
        points.commit()
        assert "open at time 1" in points("view", "open", "--at", str(first), view="old")
        assert points.json("status", view="old")["begin_time"] == first
        assert points.json("get", "pts", item, view="old") == {"v": 1.0}
        assert points.json("get", "pts", item) == {"v": 2.0}

    def test_open_at_a_future_time_is_refused(self, points: Mapctl) -> None:
        result = points.invoke("view", "open", "--at", "7")
        assert isinstance(result.exception, UsageError)
        assert points.json("view", "list") == {"views": []}

    def test_open_with_staged_changes_is_refused(self, points: Mapctl) -> None:
        points.insert({"x": 1})
        result = points.invoke("view", "open")
        assert isinstance(result.exception, ViewClosedError)
        assert "mapctl view abort" in str(result.exception)

    def test_open_in_a_named_view_names_it_in_the_hint(self, points: Mapctl) -> None:
        points.insert({"x": 1}, view="w")
        result = points.invoke("view", "open", view="w")
        assert "`mapctl --view w view abort`" in str(result.exception)

    def test_reopen_an_empty_view_moves_its_begin_time(self, points: Mapctl) -> None:
        points("view", "open", view="w")
        points.insert({"x": 1})
        points.commit()
        points("view", "open", view="w")
        assert points.json("status", view="w")["begin_time"] == 1

    def test_abort_drops_staged_changes(self, points: Mapctl) -> None:
        item = points.insert({"x": 1})
        assert "view main aborted" in points("view", "abort")
        assert points.json("view", "list") == {"views": []}
        assert isinstance(points.invoke("get", "pts", item).exception, ItemNotFound)

    def test_abort_of_no_view(self, points: Mapctl) -> None:
        result = points.invoke("view", "abort", view="ghost")
        assert isinstance(result.exception, ViewClosedError)

    def test_views_are_isolated(self, points: Mapctl) -> None:
        points.insert({"x": 1}, view="a")
        assert points.json("diff", view="b")["changes"] == []
        assert len(points.json("diff", view="a")["changes"]) == 1
        assert points.json("ls", "pts", view="b") == {"items": []}
        points.commit(view="a")
        assert len(points.json("ls", "pts", view="b")["items"]) == 1


class TestGlobalOptions:
    def test_c_help_names_its_metavar(self, mapctl: Mapctl) -> None:
        (line,) = [x for x in mapctl("--help").splitlines() if x.strip().startswith("-C ")]
        assert "-C DIRECTORY" in line
        assert "Run as if started in DIRECTORY" in line

    def test_view_help_names_its_metavar(self, mapctl: Mapctl) -> None:
        (line,) = [x for x in mapctl("--help").splitlines() if x.strip().startswith("--view ")]
        assert "--view NAME" in line
        assert "view called NAME" in line
