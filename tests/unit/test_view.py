"""The pure rules of `resolve` (`mapapi.core.view`): what settles a conflict, and
when that would discard an edit the view staged after the conflict."""

from __future__ import annotations

import pytest

from mapapi.core.change import Change, Conflict, Op
from mapapi.core.history import Revision
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId
from mapapi.core.view import View, discards, mapctl_in, settle

CHUNK = ChunkId.new()
ITEM = ItemId.new()


def theirs(*, removed: bool = False) -> Revision:
    data = b"" if removed else b"theirs"
    return Revision(ITEM, "t", CHUNK, data, 1, 5, removed, PeerId.new(), CommitId.new())


def change(op: Op, data: bytes = b"ours") -> Change:
    return Change(op, "t", ITEM, CHUNK, b"" if op is Op.REMOVE else data)


def conflict(ours: Change | None, *, removed: bool = False) -> Conflict:
    return Conflict("t", ITEM, CHUNK, None, ours, theirs(removed=removed))


class TestSettle:
    def test_ours_is_what_is_staged_now(self) -> None:
        staged = change(Op.UPDATE, b"merged")
        assert settle(conflict(change(Op.UPDATE)), staged, "ours") == staged

    def test_ours_keeps_a_removal_staged_now(self) -> None:
        staged = change(Op.REMOVE)
        assert settle(conflict(change(Op.UPDATE)), staged, "ours") == staged

    def test_ours_without_a_staged_edit_is_the_side_that_conflicted(self) -> None:
        ours = change(Op.INSERT, b"mine")
        assert settle(conflict(ours), None, "ours") == change(Op.UPDATE, b"mine")

    @pytest.mark.parametrize("removed", [False, True])
    def test_an_ours_removal(self, removed: bool) -> None:
        ours = change(Op.REMOVE)
        expected = None if removed else ours
        assert settle(conflict(ours, removed=removed), None, "ours") == expected

    def test_theirs_stages_nothing(self) -> None:
        assert settle(conflict(change(Op.UPDATE)), change(Op.UPDATE, b"m"), "theirs") is None

    def test_an_edited_payload_is_an_update(self) -> None:
        settled = settle(conflict(None), change(Op.REMOVE), "ours", b"edited")
        assert settled == change(Op.UPDATE, b"edited")


class TestDiscards:
    def test_nothing_staged_is_never_discarded(self) -> None:
        assert not discards(None, None)
        assert not discards(None, change(Op.UPDATE))

    def test_keeping_the_staged_change_discards_nothing(self) -> None:
        staged = change(Op.UPDATE, b"merged")
        assert not discards(staged, settle(conflict(change(Op.UPDATE)), staged, "ours"))

    @pytest.mark.parametrize("edited", [None, b"other"])
    def test_theirs_or_an_edit_discards_a_staged_edit(self, edited: bytes | None) -> None:
        staged = change(Op.UPDATE, b"merged")
        assert discards(staged, settle(conflict(change(Op.UPDATE)), staged, "theirs", edited))


class TestView:
    def test_staged_since_conflict_lists_only_conflicting_items(self) -> None:
        other = Change(Op.INSERT, "t", ItemId.new(), CHUNK, b"x")
        staged = change(Op.UPDATE, b"merged")
        view = View("bob", 5, changes=[other, staged], conflicts=[conflict(change(Op.UPDATE))])
        assert view.staged_since_conflict() == {ITEM: staged}

    @pytest.mark.parametrize(
        ("view", "expected"),
        [("main", "mapctl"), ("bob", "mapctl --view bob"), ("a b", "mapctl --view 'a b'")],
    )
    def test_mapctl_in(self, view: str, expected: str) -> None:
        assert mapctl_in(view) == expected
