"""`mapctl gc` (issue 14 §4): it drops the history no reader needs, stops at the
oldest open view, follows `[history] retention`, keeps a map's missions whole and
says what it freed."""

from __future__ import annotations

import json
from pathlib import Path

from mapapi.maps.g2o import read_g2o
from tests.cli.conftest import Mapctl

SAMPLES = Path(__file__).resolve().parents[2] / "sample_maps"
EXIT_USAGE = 2


def edits(points: Mapctl, count: int) -> str:
    """One point written `count` times, a commit each; its id."""
    item = points.insert({"n": 0})
    points("commit", "-m", "n = 0")
    for n in range(1, count):
        points("set", "pts", item, json.dumps({"n": n}))
        points("commit", "-m", f"n = {n}")
    return item


def values(points: Mapctl, item: str) -> list[float]:
    """The point's values, oldest first, as `log` lists its revisions."""
    return [r["data"]["n"] for r in reversed(points.json("log", "pts", item))]


def test_gc_keeps_what_reads_since_the_horizon_see_and_every_commit(points: Mapctl) -> None:
    item = edits(points, 6)  # commits at times 1..6
    commits = len(points.json("log"))

    done = points.json("gc", "--keep-since", "4")

    assert (done["horizon"], done["set_by"], done["keep"]) == (4, "asked", None)
    assert (done["revisions"], done["items"], done["chunks"]) == (3, 1, 1)  # n = 0, 1, 2
    assert done["bytes"] > 0
    assert done["store_bytes"] > 0
    assert values(points, item) == [3, 4, 5]
    assert points.json("get", "pts", item, "--at", "4")["n"] == 3
    refused = points.main("get", "pts", item, "--at", "3")
    assert refused.code == EXIT_USAGE
    assert "`mapctl gc` dropped that history" in refused.err
    assert len(points.json("log")) == commits  # the records stay
    assert points.json("fsck")["ok"] is True


def test_an_open_view_holds_the_horizon_back_until_it_closes(points: Mapctl) -> None:
    item = edits(points, 3)
    points("view", "open", view="survey")  # begins at time 3
    for n in (3, 4):
        points("set", "pts", item, json.dumps({"n": n}))
        points("commit", "-m", f"n = {n}")

    held = points.json("gc", "--keep-since", "5")

    assert (held["horizon"], held["set_by"]) == (3, "view 'survey'")
    assert values(points, item) == [2, 3, 4]
    assert points.json("get", "pts", item, view="survey")["n"] == 2  # what it began on
    points("view", "abort", view="survey")
    assert points.json("gc", "--keep-since", "5")["horizon"] == 5
    assert values(points, item) == [4]


def test_keep_and_the_retention_setting_keep_each_items_newest(points: Mapctl, repo: Path) -> None:
    item = edits(points, 5)
    refused = points.main("gc")
    assert refused.code == EXIT_USAGE
    assert "retention = N" in refused.err
    assert points.json("gc", "--keep", "3")["revisions"] == 2
    assert values(points, item) == [2, 3, 4]
    config = repo / ".mapapi" / "config.toml"
    config.write_text(config.read_text() + "\n[history]\nretention = 1\n")

    done = points.json("gc")

    assert (done["keep"], done["revisions"]) == (1, 2)
    assert values(points, item) == [4]
    out = points("gc", "--keep", "1")
    assert "dropped 0 revision(s)" in out
    assert "each item's newest 1 kept" in out


def test_bad_options_are_refused(points: Mapctl) -> None:
    edits(points, 2)
    for args, message in (
        (("--keep", "0"), "0 is not in the range"),
        (("--keep-since", "nope"), "names no commit"),
    ):
        outcome = points.main("gc", *args)
        assert outcome.code == EXIT_USAGE, outcome
        assert message in outcome.err


def test_a_map_keeps_its_missions_whole_after_gc(mapctl: Mapctl, tmp_path: Path) -> None:
    mapctl("import", str(SAMPLES / "pose_graphs" / "intel.g2o"))
    (mission,) = mapctl.json("missions")["missions"]
    chunk = mission["tiles"][0]["vertices"]
    (vertex,) = [i for i in mapctl.json("ls", "vertices", "--chunk", chunk)["items"]][:1]
    for x in (1.0, 2.0):
        moved = {**vertex["data"], "pose": {**vertex["data"]["pose"], "x": x}}
        mapctl("set", "vertices", vertex["id"], json.dumps(moved))
        mapctl("commit", "-m", f"vertex to x = {x}")
    before = mapctl.json("missions")["missions"]

    done = mapctl.json("gc", "--keep", "1")

    assert done["revisions"] == 2  # the vertex as imported and at x = 1
    assert mapctl.json("missions")["missions"] == before
    mapctl("export", "intel", "-o", str(tmp_path / "after.g2o"))
    assert read_g2o(tmp_path / "after.g2o").vertices[int(vertex["data"]["index"])][0] == 2.0
    assert mapctl.json("fsck")["ok"] is True
