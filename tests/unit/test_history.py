"""Multi-version item history (mapapi.core.history, DESIGN §4)."""

import pytest

from mapapi.core.history import (
    CommitRecord,
    ItemHistory,
    Revision,
    author_label,
    change_kind,
    changed_between,
    number_commits,
    revision_at,
    visible_at,
)
from mapapi.core.ids import ChunkId, CommitId, ItemId, PeerId

ITEM = ItemId.new()
CHUNK = ChunkId.new()
AUTHOR = PeerId.new()


def rev(time: int, data: bytes = b"x", *, removed: bool = False, inserted: int = 1) -> Revision:
    return Revision(
        ITEM, "t", CHUNK, b"" if removed else data, inserted, time, removed, AUTHOR, CommitId.new()
    )


# Inserted at 2, updated at 5, removed at 8, re-inserted at 11.
LIFE = [rev(2, b"a", inserted=2), rev(5, b"b", inserted=2), rev(8, removed=True), rev(11, b"c")]


class TestRevisionAt:
    @pytest.mark.parametrize(
        ("time", "expected"),
        [(0, None), (1, None), (2, 0), (4, 0), (5, 1), (7, 1), (8, 2), (99, 3)],
    )
    def test_newest_at_or_before_time(self, time: int, expected: int | None) -> None:
        found = revision_at(LIFE, time)
        assert found is (None if expected is None else LIFE[expected])

    def test_includes_tombstones(self) -> None:
        found = revision_at(LIFE, 9)
        assert found is not None
        assert found.removed

    def test_empty_history(self) -> None:
        assert revision_at([], 10) is None


class TestVisibleAt:
    @pytest.mark.parametrize(("time", "data"), [(1, None), (3, b"a"), (6, b"b"), (12, b"c")])
    def test_reads_the_live_version(self, time: int, data: bytes | None) -> None:
        found = visible_at(LIFE, time)
        assert (None if found is None else found.data) == data

    @pytest.mark.parametrize("time", [8, 9, 10])
    def test_tombstone_hides_the_item_until_reinserted(self, time: int) -> None:
        assert visible_at(LIFE, time) is None


class TestChangedBetween:
    def test_interval_is_open_below_closed_above(self) -> None:
        assert changed_between(LIFE, 2, 8) == [LIFE[1], LIFE[2]]

    def test_empty_interval(self) -> None:
        assert changed_between(LIFE, 5, 5) == []

    def test_everything_after(self) -> None:
        assert changed_between(LIFE, 0, 100) == LIFE


class TestChangeKind:
    def test_first_revision_is_an_insert(self) -> None:
        assert change_kind(LIFE[0], None) == "inserted"

    def test_revision_after_a_live_one_is_an_update(self) -> None:
        assert change_kind(LIFE[1], LIFE[0]) == "updated"

    def test_tombstone_is_a_removal(self) -> None:
        assert change_kind(LIFE[2], LIFE[1]) == "removed"

    def test_revision_after_a_tombstone_is_an_insert(self) -> None:
        assert change_kind(LIFE[3], LIFE[2]) == "inserted"


class TestItemHistory:
    def test_keeps_revisions_sorted_whatever_the_order_given(self) -> None:
        history = ItemHistory([LIFE[2], LIFE[0], LIFE[3]])
        history.add(LIFE[1])
        assert history.revisions == tuple(LIFE)

    def test_refuses_a_second_revision_at_the_same_time(self) -> None:
        history = ItemHistory([LIFE[0]])
        with pytest.raises(ValueError, match="already has a revision at time 2"):
            history.add(rev(2, b"other"))
        assert history.revisions == (LIFE[0],)

    def test_latest_includes_tombstones(self) -> None:
        history = ItemHistory(LIFE[:3])
        assert history.latest() is LIFE[2]
        assert ItemHistory().latest() is None

    def test_at_hides_tombstones(self) -> None:
        history = ItemHistory(LIFE)
        assert history.at(6) is LIFE[1]
        assert history.at(9) is None
        assert history.at(1) is None

    def test_revisions_is_a_read_only_snapshot(self) -> None:
        history = ItemHistory(LIFE[:1])
        snapshot = history.revisions
        history.add(LIFE[1])
        assert snapshot == (LIFE[0],)
        assert isinstance(snapshot, tuple)


def record(time: int, *, name: str = "", view: str = "") -> CommitRecord:
    return CommitRecord(CommitId.new(), time, AUTHOR, "", (CHUNK,), name, view)


class TestAuthorLabel:
    def test_name_and_view(self) -> None:
        assert author_label(record(1, name="robot1", view="bob")) == "robot1/bob"

    def test_the_main_view_is_not_repeated(self) -> None:
        assert author_label(record(1, name="robot1", view="main")) == "robot1"
        assert author_label(record(1, name="robot1")) == "robot1"

    def test_an_old_record_takes_the_known_name_then_the_short_id(self) -> None:
        assert author_label(record(1), known="robot2") == "robot2"
        assert author_label(record(1)) == AUTHOR.short

    def test_the_stored_name_wins_over_the_known_one(self) -> None:
        assert author_label(record(1, name="robot1"), known="renamed") == "robot1"


class TestNumberCommits:
    def test_numbers_run_1_to_n_in_commit_order(self) -> None:
        records = [record(725), record(97), record(193)]
        numbers = number_commits(records)
        assert [numbers[r.id] for r in records] == [3, 1, 2]

    def test_equal_times_are_ordered_by_id(self) -> None:
        a, b = sorted([record(5), record(5)], key=lambda r: r.id)
        assert number_commits([b, a]) == {a.id: 1, b.id: 2}

    def test_no_commits(self) -> None:
        assert number_commits([]) == {}
