"""`mapctl query-bbox` off the network, and the spatial index options of `init`
(issue 4 §3-4). A repository with no running peer searches the chunks it holds;
the swarm path is tested in tests/swarm/test_spatial.py and
tests/multiproc/test_lookup_processes.py."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from click.testing import CliRunner

from mapapi import Repository
from mapapi.lookup.spatial import BBox, SpatialGrid
from mapctl.cli import cli

from .conftest import STRUCT, InProcessDaemon, Mapctl, run_main

EXIT_USAGE = 2


@pytest.fixture
def rooms(mapctl: Mapctl) -> tuple[Mapctl, str, str]:
    """Two chunks of rooms: a hall near the origin and a lab far to the west, and
    an unplaced note in the hall's chunk."""
    mapctl("table", "create", "rooms", "--type", STRUCT)
    hall = mapctl("chunk", "create", "rooms").strip()
    lab = mapctl("chunk", "create", "rooms").strip()
    for chunk, box in ((hall, [0, 0, 0, 20, 4, 3]), (hall, [20, 0, 0, 24, 30, 3])):
        mapctl("set", "rooms", "--chunk", chunk, json.dumps({"bbox": box}))
    mapctl("set", "rooms", "--chunk", lab, json.dumps({"bbox": [-300, 200, 0, -280, 230, 4]}))
    mapctl("set", "rooms", "--chunk", hall, json.dumps({"note": "no bbox, not placed"}))
    mapctl.commit("rooms")
    return mapctl, hall, lab


class TestQueryBbox:
    def test_lists_the_overlapping_chunks_with_box_and_holder(
        self, rooms: tuple[Mapctl, str, str]
    ) -> None:
        mapctl, hall, _ = rooms
        me = Repository.find(mapctl.repo).config.peer_id

        found = mapctl.json("query-bbox", "22", "25", "1", "40", "40", "2")

        assert found == {
            "results": [
                {
                    "ref": hall,
                    "kind": "chunk",
                    "chunk": hall,
                    "table": "rooms",
                    "missions": [],
                    "bbox": [0.0, 0.0, 0.0, 24.0, 30.0, 3.0],
                    "holders": [{"id": me, "name": "bench", "address": ""}],
                    "held": True,
                }
            ]
        }

    def test_negative_coordinates_and_a_box_over_everything(
        self, rooms: tuple[Mapctl, str, str]
    ) -> None:
        mapctl, hall, lab = rooms
        west = mapctl.json("query-bbox", "-290", "210", "-1", "-285", "215", "1")
        assert [r["chunk"] for r in west["results"]] == [lab]
        everything = mapctl.json("query-bbox", "-5000", "-5000", "-500", "5000", "5000", "500")
        assert [r["chunk"] for r in everything["results"]] == sorted([hall, lab])

    def test_touching_faces_overlap(self, rooms: tuple[Mapctl, str, str]) -> None:
        mapctl, hall, _ = rooms
        touching = mapctl.json("query-bbox", "24", "30", "3", "25", "31", "4")
        assert [r["chunk"] for r in touching["results"]] == [hall]

    def test_an_empty_region_and_a_box_fully_outside_the_bounds(
        self, rooms: tuple[Mapctl, str, str]
    ) -> None:
        mapctl, _, _ = rooms
        assert mapctl.json("query-bbox", "100", "100", "0", "101", "101", "1") == {"results": []}
        outside = ("2000", "2000", "0", "3000", "3000", "1")
        assert mapctl.json("query-bbox", *outside) == {"results": []}
        assert "nothing found" in mapctl("query-bbox", *outside)

    def test_table_filter(self, rooms: tuple[Mapctl, str, str]) -> None:
        mapctl, hall, _ = rooms
        mapctl("table", "create", "notes", "--type", STRUCT)
        mapctl("chunk", "create", "notes")
        mapctl("set", "notes", json.dumps({"bbox": [1, 1, 1, 2, 2, 2]}))
        mapctl.commit("a note in the hall")
        box = ("0", "0", "0", "3", "3", "3")
        assert {r["table"] for r in mapctl.json("query-bbox", *box)["results"]} == {
            "rooms",
            "notes",
        }
        only = mapctl.json("query-bbox", *box, "--table", "rooms")["results"]
        assert [r["chunk"] for r in only] == [hall]

    def test_the_table_view_names_the_chunks(self, rooms: tuple[Mapctl, str, str]) -> None:
        mapctl, hall, lab = rooms
        shown = mapctl("query-bbox", "-5000", "-5000", "-500", "5000", "5000", "500")
        assert hall[:8] in shown
        assert lab[:8] in shown
        assert "x -300..-280 y 200..230 z 0..4" in shown

    def test_the_table_view_rounds_the_box_onto_one_line(self, mapctl: Mapctl) -> None:
        mapctl("table", "create", "rooms", "--type", STRUCT)
        mapctl("chunk", "create", "rooms")
        box = [-12.345678901, 0.123456789, -0.04, 12.3456789012, 7.777777777, 2.0000001]
        mapctl("set", "rooms", json.dumps({"bbox": box}))
        mapctl.commit("an odd room")

        query = ("query-bbox", "-20", "-20", "-1", "20", "20", "3")
        shown = mapctl(*query)

        # rounded outwards to 0.1 m, so the box shown contains the one stored
        line = next(line for line in shown.splitlines() if "rooms" in line)
        assert "x -12.4..12.4 y 0.1..7.8 z -0.1..2.1" in line
        assert mapctl.json(*query)["results"][0]["bbox"] == box  # --json: full precision

    def test_a_chunk_of_vertices_lists_its_missions(self, mapctl: Mapctl) -> None:
        mapctl("table", "create", "vertices", "--type", "mapapi.v1.Vertex")
        chunk = mapctl("chunk", "create", "vertices").strip()
        for index, (mission, x) in enumerate((("hall", 1.0), ("lab", 2.0), ("hall", 3.0))):
            vertex = {"mission": mission, "index": index, "pose": {"x": x, "qw": 1}}
            mapctl("set", "vertices", json.dumps(vertex))
        mapctl("set", "vertices", json.dumps({"index": 9, "pose": {"x": 2.5}}))  # no mission
        mapctl.commit("vertices of two missions")

        (found,) = mapctl.json("query-bbox", "0", "-1", "-1", "4", "1", "1")["results"]

        assert (found["chunk"], found["missions"], found["kind"]) == (
            chunk,
            ["hall", "lab"],
            "mission",
        )
        assert "hall, lab" in mapctl("query-bbox", "0", "-1", "-1", "4", "1", "1")


class TestQueryBboxInASwarm:
    async def test_holders_of_chunks_held_elsewhere_carry_their_names(
        self, daemon: InProcessDaemon, tmp_path: Path
    ) -> None:
        other = InProcessDaemon(Repository.init(tmp_path / "other", "other").root)
        record = await other.start()
        try:
            await daemon.json("join", record.join)
            await other("table", "create", "rooms", "--type", STRUCT)
            chunk = (await other.json("chunk", "create", "rooms"))["id"]
            await other("set", "rooms", json.dumps({"bbox": [0, 0, 0, 1, 1, 1]}))
            await other("commit", "-m", "a room")

            found = await daemon.json("query-bbox", "0", "0", "0", "1", "1", "1")
            shown = await daemon("query-bbox", "0", "0", "0", "1", "1", "1")
            verbose = await daemon("-v", "query-bbox", "0", "0", "0", "1", "1", "1")
        finally:
            await other.close()

        (result,) = found["results"]
        assert (result["chunk"], result["held"]) == (chunk, False)
        assert result["holders"] == [{"id": record.id, "name": "other", "address": record.address}]
        assert "other" in shown.out
        assert f"other ({record.id[:8]})" in verbose.out

    @pytest.mark.parametrize(
        ("bbox", "message"),
        [
            (("1", "0", "0", "0", "1", "1"), "xmin 1.0 > xmax 0.0"),
            (("0", "0", "0", "nan", "1", "1"), "xmax must be finite"),
            (("0", "0", "0", "inf", "1", "1"), "xmax must be finite"),
        ],
    )
    def test_an_invalid_box_is_a_usage_error(
        self, rooms: tuple[Mapctl, str, str], bbox: tuple[str, ...], message: str
    ) -> None:
        mapctl, _, _ = rooms
        outcome = mapctl.main("query-bbox", *bbox)
        assert outcome.code == EXIT_USAGE
        assert len(outcome.err_lines) == 1
        assert outcome.err_lines[0].startswith(f"error: bbox {message}")

    def test_five_numbers_are_a_usage_error(self, mapctl: Mapctl) -> None:
        outcome = mapctl.main("query-bbox", "0", "0", "0", "1", "1")
        assert outcome.code == EXIT_USAGE
        assert "takes 6 values" in outcome.err

    def test_load_of_chunks_held_here_needs_no_peer(self, rooms: tuple[Mapctl, str, str]) -> None:
        mapctl, hall, _ = rooms
        found = mapctl.json("query-bbox", "0", "0", "0", "1", "1", "1", "--load")
        assert [(r["chunk"], r["held"]) for r in found["results"]] == [(hall, True)]
        assert found["loaded"] == []


class TestInitSpatialIndex:
    def test_defaults_are_written_to_the_config(self, repo: Path) -> None:
        config = Repository.find(repo).config
        assert config.spatial == SpatialGrid()
        text = (repo / ".mapapi" / "config.toml").read_text()
        assert "[spatial]" in text
        assert "cells = [32, 32, 1]" in text

    def test_bounds_and_cells_are_kept(self, tmp_path: Path) -> None:
        path = tmp_path / "garage"
        args = ["init", str(path), "--bounds", "-50", "-80", "-5", "150", "70", "20"]
        result = CliRunner().invoke(cli, [*args, "--cells", "16", "8", "2", "--json"])
        assert result.exit_code == 0, result.output
        assert json.loads(result.stdout)["spatial"] == {
            "bounds": [-50.0, -80.0, -5.0, 150.0, 70.0, 20.0],
            "cells": [16, 8, 2],
        }
        grid = Repository.find(path).config.spatial
        assert grid == SpatialGrid(BBox(-50, -80, -5, 150, 70, 20), (16, 8, 2))

    @pytest.mark.parametrize(
        ("options", "message"),
        [
            (["--bounds", "0", "0", "0", "0", "10", "10"], "positive extent"),
            (["--bounds", "5", "0", "0", "1", "10", "10"], "xmin 5.0 > xmax 1.0"),
            (["--cells", "0", "4", "1"], "cell counts must be three integers >= 1"),
            (["--cells", "2048", "2048", "1"], "exceed the limit"),
        ],
    )
    def test_a_bad_index_is_refused_and_creates_nothing(
        self, tmp_path: Path, options: list[str], message: str
    ) -> None:
        path = tmp_path / "bad"
        outcome = run_main(["init", str(path), *options])
        assert outcome.code == EXIT_USAGE
        assert message in outcome.err
        assert not (path / ".mapapi").exists()

    def test_a_damaged_spatial_table_is_a_clear_error(self, mapctl: Mapctl) -> None:
        config = mapctl.repo / ".mapapi" / "config.toml"
        config.write_text(config.read_text().replace("cells = [32, 32, 1]", 'cells = "many"'))
        outcome = mapctl.main("query-bbox", "0", "0", "0", "1", "1", "1")
        assert outcome.code != 0
        assert "config.toml is damaged" in outcome.err
        assert "cell counts" in outcome.err
