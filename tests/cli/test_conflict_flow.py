"""The git-like conflict flow with two named views on one repository.

Views `alice` and `bob` begin at the same time and change the same items;
alice commits first, so bob's commit conflicts (exit 3) and keeps the
conflicts in his view for `diff`, `resolve` and a second `commit`.
"""

from __future__ import annotations

import json
import types
from typing import Any

import click
import pytest

from mapapi import ConflictError, UnresolvedConflicts, UsageError, ViewClosedError
from mapctl.commands import view as view_commands
from tests.cli.conftest import STRUCT, InProcessDaemon, Mapctl

BASE = {"x": 1.0, "label": "dock"}
ALICE = {"x": 2.0, "label": "dock"}
BOB = {"x": 3.0, "label": "charger"}


def _seed(points: Mapctl, *values: dict[str, Any]) -> list[str]:
    """Commit items, then open both views at the same time."""
    ids = [points.insert(v) for v in values]
    points.commit("seed")
    points("view", "open", view="alice")
    points("view", "open", view="bob")
    return ids


def _conflict(points: Mapctl, *values: dict[str, Any]) -> list[str]:
    """Both views update every seeded item; alice commits, bob's commit conflicts."""
    ids = _seed(points, *values)
    for item in ids:
        points("set", "pts", item, json.dumps(ALICE), view="alice")
        points("set", "pts", item, json.dumps(BOB), view="bob")
    points.commit("alice", view="alice")
    result = points.invoke("commit", "-m", "bob", view="bob")
    assert isinstance(result.exception, ConflictError)
    return ids


class TestFailedCommit:
    def test_second_commit_exits_3_and_prints_conflicts(self, points: Mapctl) -> None:
        (item,) = _seed(points, BASE)
        points("set", "pts", item, json.dumps(ALICE), view="alice")
        points("set", "pts", item, json.dumps(BOB), view="bob")
        assert points.commit("alice", view="alice")["commit"]
        outcome = points.main("commit", "-m", "bob", "--json", view="bob")
        assert outcome.code == 3
        assert json.loads(outcome.out) == {
            "conflicts": [
                {
                    "table": "pts",
                    "id": item,
                    "chunk": points.json("chunk", "list")["chunks"][0]["id"],
                    "base": BASE,
                    "ours": BOB,
                    "theirs": ALICE,
                }
            ]
        }
        assert outcome.err_lines == [
            "error: 1 conflicting item(s); run `mapctl --view bob diff` and "
            "`mapctl --view bob resolve`, then commit again"
        ]

    def test_the_default_view_keeps_the_short_hint(self, points: Mapctl) -> None:
        item = points.insert(BASE)
        points.commit("seed")
        points("view", "open", view="alice")
        points("set", "pts", item, json.dumps(ALICE), view="alice")
        points("set", "pts", item, json.dumps(BOB))
        points.commit("alice", view="alice")
        outcome = points.main("commit")
        assert outcome.code == 3
        assert outcome.err_lines == [
            "error: 1 conflicting item(s); run `mapctl diff` and `mapctl resolve`, "
            "then commit again"
        ]
        refused = points.main("commit")
        assert "run `mapctl diff`, then `mapctl resolve`" in refused.err
        assert "run `mapctl diff`" in points("status")

    def test_a_view_name_is_quoted_for_the_shell(self, points: Mapctl) -> None:
        item = points.insert(BASE)
        points.commit("seed")
        points("view", "open", view="bob's")
        points("set", "pts", item, json.dumps(ALICE))
        points("set", "pts", item, json.dumps(BOB), view="bob's")
        points.commit("main")
        outcome = points.main("commit", view="bob's")
        assert "run `mapctl --view 'bob'\"'\"'s' diff`" in outcome.err

    def test_diff_json_shows_base_ours_theirs(self, points: Mapctl) -> None:
        (item,) = _conflict(points, BASE)
        diff = points.json("diff", view="bob")
        assert diff["view"] == "bob"
        assert diff["changes"] == []
        (conflict,) = diff["conflicts"]
        assert (conflict["table"], conflict["id"]) == ("pts", item)
        assert (conflict["base"], conflict["ours"], conflict["theirs"]) == (BASE, BOB, ALICE)
        status = points.json("status", view="bob")
        assert status["conflicts"] == [item]
        assert points.json("view", "list")["views"][0]["conflicts"] == 1
        shown = points("status", view="bob")
        assert "1 unresolved conflict(s): run `mapctl --view bob diff`" in shown

    def test_diff_plain_renders_the_conflict(self, points: Mapctl) -> None:
        (item,) = _conflict(points, BASE)
        out = points("diff", view="bob")
        assert f"conflict pts {item}" in out
        for word in ("base", "ours", "theirs", "charger"):
            assert word in out

    def test_commit_refuses_until_resolved(self, points: Mapctl) -> None:
        _conflict(points, BASE)
        outcome = points.main("commit", view="bob")
        assert outcome.code == 3
        assert "run `mapctl --view bob diff`, then `mapctl --view bob resolve`" in outcome.err
        assert isinstance(points.invoke("commit", view="bob").exception, UnresolvedConflicts)

    def test_the_view_begins_again_after_the_conflict(self, points: Mapctl) -> None:
        (item,) = _conflict(points, BASE)
        assert points.json("status", view="bob")["begin_time"] == 2
        assert points.json("get", "pts", item, view="bob") == ALICE  # theirs, until resolved

    def test_abort_drops_the_conflicts(self, points: Mapctl) -> None:
        (item,) = _conflict(points, BASE)
        points("view", "abort", view="bob")
        assert points.json("view", "list")["views"] == []
        assert points.json("get", "pts", item) == ALICE


class TestResolve:
    def test_ours_then_commit_keeps_ours(self, points: Mapctl) -> None:
        (item,) = _conflict(points, BASE)
        assert points.json("resolve", "--ours", view="bob") == {"resolved": [item], "remaining": 0}
        assert points.json("diff", view="bob")["conflicts"] == []
        record = points.commit("bob again", view="bob")
        assert record["commit"]
        assert points.json("get", "pts", item) == BOB
        assert points.json("view", "list")["views"] == []

    def test_theirs_then_commit_keeps_theirs(self, points: Mapctl) -> None:
        (item,) = _conflict(points, BASE)
        assert "resolved 1 conflict(s); 0 left" in points("resolve", "--theirs", view="bob")
        assert points.json("status", view="bob")["staged"] == []
        assert points.commit("bob again", view="bob") == {"commit": None}  # nothing to write
        assert points.json("get", "pts", item) == ALICE
        assert points.json("view", "list")["views"] == []
        assert [c["message"] for c in points.json("log")] == ["alice", "seed"]

    def test_resolve_one_of_two_leaves_one(self, points: Mapctl) -> None:
        first, second = _conflict(points, BASE, {"x": 10.0})
        assert len(points.json("diff", view="bob")["conflicts"]) == 2
        resolved = points.json("resolve", "--ours", first[:6], view="bob")
        assert resolved == {"resolved": [first], "remaining": 1}
        assert [c["id"] for c in points.json("diff", view="bob")["conflicts"]] == [second]
        assert points.main("commit", view="bob").code == 3
        points("resolve", "--theirs", second, view="bob")
        points.commit(view="bob")
        assert points.json("get", "pts", first) == BOB
        assert points.json("get", "pts", second) == ALICE

    def test_resolve_an_id_without_conflict(self, points: Mapctl) -> None:
        _conflict(points, BASE)
        result = points.invoke("resolve", "--ours", "ffff", view="bob")
        assert isinstance(result.exception, UsageError)
        assert "0 of the view's conflicts" in str(result.exception)

    def test_resolve_without_conflicts(self, points: Mapctl) -> None:
        points.insert({"x": 1})
        result = points.invoke("resolve", "--ours")
        assert isinstance(result.exception, ViewClosedError)

    def test_staged_changes_survive_the_failed_commit(self, points: Mapctl) -> None:
        item, other = _seed(points, BASE, {"y": 1.0})
        points("set", "pts", item, json.dumps(ALICE), view="alice")
        points.commit(view="alice")
        points("set", "pts", item, json.dumps(BOB), view="bob")
        points("set", "pts", other, '{"y": 2.0}', view="bob")
        points("rm", "pts", other, view="bob")
        added = points.insert({"z": 1.0}, view="bob")
        assert isinstance(points.invoke("commit", view="bob").exception, ConflictError)
        staged = points.json("status", view="bob")["staged"]
        assert [(s["op"], s["id"]) for s in staged] == [("remove", other), ("insert", added)]
        changes = points.json("diff", view="bob")["changes"]
        assert [(c["op"], c["base"], c["ours"]) for c in changes] == [
            ("remove", {"y": 1.0}, None),
            ("insert", None, {"z": 1.0}),
        ]
        points("resolve", "--ours", view="bob")
        record = points.commit("bob", view="bob")
        shown = points.json("show", record["commit"])
        assert sorted((c["op"], c["id"]) for c in shown["changes"]) == sorted(
            [("updated", item), ("removed", other), ("inserted", added)]
        )
        assert points.json("get", "pts", added) == {"z": 1.0}
        assert sorted(r["id"] for r in points.json("ls", "pts")["items"]) == sorted([item, added])


MERGED = {"x": 2.5, "label": "charger"}


def _edit_after(points: Mapctl, *values: dict[str, Any]) -> list[str]:
    """A conflict in bob's view, then bob stages his own merge of the first item."""
    ids = _conflict(points, *values)
    points("set", "pts", ids[0], json.dumps(MERGED), view="bob")
    return ids


class TestEditStagedAfterTheConflict:
    """`resolve` never discards what the view staged after the conflict without a choice."""

    def test_ours_keeps_the_edit_staged_now(self, points: Mapctl) -> None:
        (item,) = _edit_after(points, BASE)
        assert points.json("resolve", "--ours", view="bob") == {"resolved": [item], "remaining": 0}
        points.commit("bob merged", view="bob")
        assert points.json("get", "pts", item) == MERGED

    def test_ours_keeps_a_removal_staged_now(self, points: Mapctl) -> None:
        (item,) = _conflict(points, BASE)
        points("rm", "pts", item, view="bob")
        points("resolve", "--ours", view="bob")
        points.commit(view="bob")
        assert points.json("ls", "pts") == {"items": []}

    def test_theirs_refuses_with_the_command_to_run(self, points: Mapctl) -> None:
        (item,) = _edit_after(points, BASE)
        outcome = points.main("resolve", "--theirs", view="bob")
        assert outcome.code == 2
        (line,) = outcome.err_lines
        assert item in line
        assert "`mapctl --view bob resolve --theirs --force`" in line
        assert [c["id"] for c in points.json("diff", view="bob")["conflicts"]] == [item]
        assert points.json("get", "pts", item, view="bob") == MERGED

    def test_the_refusal_repeats_the_ids_given(self, points: Mapctl) -> None:
        first, _second = _edit_after(points, BASE, {"x": 10.0})
        outcome = points.main("resolve", "--theirs", first[:6], view="bob")
        assert outcome.code == 2
        assert f"`mapctl --view bob resolve --theirs --force {first}`" in outcome.err

    def test_nothing_is_resolved_when_one_item_refuses(self, points: Mapctl) -> None:
        first, second = _edit_after(points, BASE, {"x": 10.0})
        assert points.main("resolve", "--theirs", view="bob").code == 2
        conflicts = points.json("diff", view="bob")["conflicts"]
        assert sorted(c["id"] for c in conflicts) == sorted([first, second])

    def test_theirs_force_discards_the_edit(self, points: Mapctl) -> None:
        (item,) = _edit_after(points, BASE)
        assert points.json("resolve", "--theirs", "--force", view="bob")["remaining"] == 0
        assert points.commit(view="bob") == {"commit": None}
        assert points.json("get", "pts", item) == ALICE

    async def test_through_the_peer_daemon(self, daemon: InProcessDaemon) -> None:
        for args in (("table", "create", "pts", "--type", STRUCT), ("chunk", "create", "pts")):
            assert (await daemon(*args)).code == 0
        item = (await daemon.json("set", "pts", json.dumps(BASE)))["id"]
        assert (await daemon("commit")).code == 0
        for view, value in (("alice", ALICE), ("bob", BOB)):
            assert (await daemon("view", "open", view=view)).code == 0
            assert (await daemon("set", "pts", item, json.dumps(value), view=view)).code == 0
        assert (await daemon("commit", view="alice")).code == 0
        assert (await daemon("commit", view="bob")).code == 3
        assert (await daemon("set", "pts", item, json.dumps(MERGED), view="bob")).code == 0
        refused = await daemon("resolve", "--theirs", view="bob")
        assert refused.code == 2
        assert "`mapctl --view bob resolve --theirs --force`" in refused.err
        assert (await daemon("resolve", "--theirs", "--force", view="bob")).code == 0
        assert await daemon.json("get", "pts", item, view="bob") == ALICE

    def test_diff_shows_the_staged_edit_as_ours(self, points: Mapctl) -> None:
        (item,) = _edit_after(points, BASE)
        out = points("diff", view="bob")
        assert f"conflict pts {item}" in out
        assert "ours (staged)" in out
        assert "2.5" in out


class TestRemoveVersusUpdate:
    def test_they_removed_we_updated(self, points: Mapctl) -> None:
        (item,) = _seed(points, BASE)
        points("rm", "pts", item, view="alice")
        points.commit("alice removes", view="alice")
        points("set", "pts", item, json.dumps(BOB), view="bob")
        outcome = points.main("commit", "--json", view="bob")
        assert outcome.code == 3
        (conflict,) = json.loads(outcome.out)["conflicts"]
        assert (conflict["base"], conflict["ours"], conflict["theirs"]) == (BASE, BOB, None)
        (shown,) = points.json("diff", view="bob")["conflicts"]
        assert shown["theirs"] is None
        points("resolve", "--ours", view="bob")
        points.commit(view="bob")
        assert points.json("get", "pts", item) == BOB

    def test_we_removed_they_updated(self, points: Mapctl) -> None:
        (item,) = _seed(points, BASE)
        points("set", "pts", item, json.dumps(ALICE), view="alice")
        points.commit(view="alice")
        points("rm", "pts", item, view="bob")
        assert isinstance(points.invoke("commit", view="bob").exception, ConflictError)
        (conflict,) = points.json("diff", view="bob")["conflicts"]
        assert (conflict["base"], conflict["ours"], conflict["theirs"]) == (BASE, None, ALICE)
        points("resolve", "--ours", view="bob")
        points.commit(view="bob")
        assert points.json("ls", "pts") == {"items": []}

    def test_we_removed_they_updated_keep_theirs(self, points: Mapctl) -> None:
        (item,) = _seed(points, BASE)
        points("set", "pts", item, json.dumps(ALICE), view="alice")
        points.commit(view="alice")
        points("rm", "pts", item, view="bob")
        points.invoke("commit", view="bob")
        points("resolve", "--theirs", view="bob")
        points.commit(view="bob")
        assert points.json("get", "pts", item) == ALICE


class _Terminal:
    """Stands in for `sys` inside `mapctl.commands.view`: stdin is a terminal."""

    stdin = types.SimpleNamespace(isatty=lambda: True)


class TestInteractiveResolve:
    def test_no_terminal_and_no_flag_is_a_usage_error(self, points: Mapctl) -> None:
        _conflict(points, BASE)
        result = points.invoke("resolve", view="bob", input="o\n")
        assert isinstance(result.exception, UsageError)
        outcome = points.main("resolve", view="bob", input="o\n")
        assert outcome.code == 2
        assert len(outcome.err_lines) == 1
        assert "--ours" in outcome.err
        assert "--theirs" in outcome.err
        assert len(points.json("diff", view="bob")["conflicts"]) == 1

    @pytest.fixture
    def tty(self, monkeypatch: pytest.MonkeyPatch) -> None:
        monkeypatch.setattr(view_commands, "sys", _Terminal)

    @pytest.mark.usefixtures("tty")
    @pytest.mark.parametrize(("answer", "expected"), [("o", BOB), ("t", ALICE)])
    def test_ours_or_theirs(self, points: Mapctl, answer: str, expected: dict[str, Any]) -> None:
        (item,) = _conflict(points, BASE)
        out = points("resolve", view="bob", input=f"{answer}\n")
        assert "keep [o]urs, [t]heirs, [e]dit, [s]kip" in out
        assert "resolved 1 conflict(s); 0 left" in out
        points.commit(view="bob")
        assert points.json("get", "pts", item) == expected

    @pytest.mark.usefixtures("tty")
    def test_skip_leaves_the_conflict(self, points: Mapctl) -> None:
        first, second = _conflict(points, BASE, {"x": 10.0})
        out = points("resolve", view="bob", input="s\nt\n")
        assert "resolved 1 conflict(s); 1 left" in out
        assert [c["id"] for c in points.json("diff", view="bob")["conflicts"]] == [first]
        assert points.json("get", "pts", second, view="bob") == ALICE

    @pytest.mark.usefixtures("tty")
    def test_only_the_ids_given_are_asked(self, points: Mapctl) -> None:
        _first, second = _conflict(points, BASE, {"x": 10.0})
        out = points("resolve", second, view="bob", input="o\n")
        assert out.count("keep [o]urs") == 1
        assert points.json("resolve", "--theirs", view="bob")["remaining"] == 0

    @pytest.mark.usefixtures("tty")
    def test_edit_in_the_editor(self, points: Mapctl, monkeypatch: pytest.MonkeyPatch) -> None:
        (item,) = _conflict(points, BASE)
        seen: list[str] = []

        def edit(text: str, extension: str = ".txt") -> str:
            seen.append(text)
            assert extension == ".json"
            return json.dumps({"x": 4.0, "label": "merged"})

        monkeypatch.setattr(click, "edit", edit)
        points("resolve", view="bob", input="e\n")
        assert json.loads(seen[0]) == BOB  # the editor starts from ours
        points.commit(view="bob")
        assert points.json("get", "pts", item) == {"label": "merged", "x": 4.0}

    @pytest.mark.usefixtures("tty")
    def test_edit_closed_without_saving_skips(
        self, points: Mapctl, monkeypatch: pytest.MonkeyPatch
    ) -> None:
        _conflict(points, BASE)
        monkeypatch.setattr(click, "edit", lambda text, extension=".txt": None)
        assert "resolved 0 conflict(s); 1 left" in points("resolve", view="bob", input="e\n")
        assert len(points.json("diff", view="bob")["conflicts"]) == 1

    @pytest.mark.usefixtures("tty")
    def test_edit_of_a_removal_starts_from_theirs(
        self, points: Mapctl, monkeypatch: pytest.MonkeyPatch
    ) -> None:
        (item,) = _seed(points, BASE)
        points("set", "pts", item, json.dumps(ALICE), view="alice")
        points.commit(view="alice")
        points("rm", "pts", item, view="bob")
        points.invoke("commit", view="bob")
        seen: list[str] = []

        def edit(text: str, extension: str = ".txt") -> str:
            seen.append(text)
            return text

        monkeypatch.setattr(click, "edit", edit)
        points("resolve", view="bob", input="e\n")
        assert json.loads(seen[0]) == ALICE
        points.commit(view="bob")
        assert points.json("get", "pts", item) == ALICE


class TestInteractiveResolveOfAStagedEdit:
    """On a terminal, a choice that would discard an edit staged after the conflict asks."""

    @pytest.fixture(autouse=True)
    def tty(self, monkeypatch: pytest.MonkeyPatch) -> None:
        monkeypatch.setattr(view_commands, "sys", _Terminal)

    def test_ours_keeps_the_staged_edit(self, points: Mapctl) -> None:
        (item,) = _edit_after(points, BASE)
        out = points("resolve", view="bob", input="o\n")
        assert "ours (staged)" in out
        points.commit(view="bob")
        assert points.json("get", "pts", item) == MERGED

    @pytest.mark.parametrize(("confirm", "expected"), [("n", MERGED), ("y", ALICE)])
    def test_theirs_asks_first(
        self, points: Mapctl, confirm: str, expected: dict[str, Any]
    ) -> None:
        (item,) = _edit_after(points, BASE)
        out = points("resolve", view="bob", input=f"t\n{confirm}\n")
        assert f"discard the edit of {item} staged after the conflict" in out
        assert points.json("get", "pts", item, view="bob") == expected
        remaining = points.json("diff", view="bob")["conflicts"]
        assert len(remaining) == (1 if confirm == "n" else 0)

    def test_edit_starts_from_the_staged_edit(
        self, points: Mapctl, monkeypatch: pytest.MonkeyPatch
    ) -> None:
        (item,) = _edit_after(points, BASE)
        seen: list[str] = []

        def edit(text: str, extension: str = ".txt") -> str:
            seen.append(text)
            return json.dumps({"x": 2.75})

        monkeypatch.setattr(click, "edit", edit)
        points("resolve", view="bob", input="e\n")
        assert json.loads(seen[0]) == MERGED
        points.commit(view="bob")
        assert points.json("get", "pts", item) == {"x": 2.75}


class TestSerializableView:
    """A serializable view validates reads made by earlier commands (no write skew)."""

    def test_reads_of_earlier_commands_are_validated(self, mapctl: Mapctl, points: Mapctl) -> None:
        x = mapctl.insert({"balance": 50})
        y = mapctl.insert({"balance": 50})
        mapctl.commit("accounts")
        for view in ("a", "b"):
            mapctl("view", "open", "--serializable", view=view)
            mapctl("get", "pts", x, view=view)
            mapctl("get", "pts", y, view=view)
        # Each view debits a different account, keeping x + y >= 0 as it sees it.
        mapctl("set", "pts", x, '{"balance": -50}', view="a")
        mapctl("set", "pts", y, '{"balance": -50}', view="b")
        mapctl.commit("a debits x", view="a")
        refused = mapctl.main("commit", "-m", "b debits y", view="b")
        assert refused.code == 3
        assert mapctl.json("get", "pts", y) == {"balance": 50.0}

    def test_snapshot_view_does_not_validate_reads(self, mapctl: Mapctl, points: Mapctl) -> None:
        x = mapctl.insert({"balance": 50})
        y = mapctl.insert({"balance": 50})
        mapctl.commit("accounts")
        for view in ("a", "b"):
            mapctl("view", "open", view=view)
            mapctl("get", "pts", x, view=view)
        mapctl("set", "pts", x, '{"balance": -50}', view="a")
        mapctl("set", "pts", y, '{"balance": -50}', view="b")
        mapctl.commit("a", view="a")
        mapctl.commit("b", view="b")
        assert mapctl.json("get", "pts", y) == {"balance": -50.0}
