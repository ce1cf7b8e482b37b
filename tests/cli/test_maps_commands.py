"""`mapctl import`, `export`, `missions` and `plot` (issue 5 §4): on a repository
alone, with the console script's exit codes, and through a running peer daemon."""

from __future__ import annotations

from pathlib import Path

import pytest

from mapapi import Repository
from tests.cli.conftest import InProcessDaemon, Mapctl

SAMPLES = Path(__file__).resolve().parents[2] / "sample_maps"
INTEL = SAMPLES / "pose_graphs" / "intel.g2o"
TUNNELS = SAMPLES / "kimera_multi_tunnels_8robots"
ROOM = SAMPLES / "point_clouds" / "room_scan1.pcd"
LOG = SAMPLES / "laser_logs" / "intel-head.clf.bz2"
EXIT_USAGE, EXIT_NETWORK = 2, 5
PNG = b"\x89PNG\r\n\x1a\n"


@pytest.fixture
def intel(mapctl: Mapctl) -> Mapctl:
    """The CLI driver on a repository holding the Intel graph (robot "hahnel")."""
    mapctl("import", str(INTEL), "--robot", "hahnel")
    return mapctl


class TestImport:
    def test_a_g2o_file_is_one_mission_in_one_commit(self, mapctl: Mapctl) -> None:
        info = mapctl.json("import", str(INTEL), "--robot", "hahnel")

        assert (info["path"], info["format"], info["elements"]) == (str(INTEL), "g2o", 4_240)
        (mission,) = info["missions"]
        assert {k: mission[k] for k in ("name", "robot", "vertices", "edges", "points")} == {
            "name": "intel",
            "robot": "hahnel",
            "vertices": 1_728,
            "edges": 2_512,
            "points": 0,
        }
        assert set(mission["chunks"]) == {"missions", "frames"}  # the graph is in tiles
        assert [t["vertex_count"] for t in mission["tiles"]] == [432] * 4
        assert sum(t["edge_count"] for t in mission["tiles"]) == 2_512
        held = {c["id"]: c["items"] for c in mapctl.json("chunk", "list")["chunks"]}
        for tile in mission["tiles"]:
            assert held[tile["vertices"]] == tile["vertex_count"]
            assert held[tile["edges"]] == tile["edge_count"]
        assert [c["commit"] for c in mapctl.json("log")] == [mission["commit"]]

    def test_a_kimera_folder_is_one_mission_per_robot(self, mapctl: Mapctl) -> None:
        info = mapctl.json("import", str(TUNNELS), "--mission", "tunnels-")
        assert info["format"] == "kimera-csv"
        assert [m["name"] for m in info["missions"]] == [f"tunnels-robot{i}" for i in range(8)]
        assert sum(m["vertices"] for m in info["missions"]) == 1_255
        assert len(mapctl.json("log")) == 8

    def test_a_carmen_log_is_a_trajectory_with_its_scans(
        self, mapctl: Mapctl, tmp_path: Path
    ) -> None:
        info = mapctl.json("import", str(LOG), "--robot", "hahnel")
        assert (info["format"], info["elements"]) == ("carmen", 671 + 670)
        (mission,) = info["missions"]
        assert (mission["name"], mission["vertices"], mission["points"]) == (
            "intel-head",
            671,
            info["points"],
        )
        assert set(mission["chunks"]) == {"missions", "frames", "pointclouds"}
        (listed,) = mapctl.json("missions")["missions"]
        assert (listed["kind"], listed["edges"], listed["points"]) == ("graph", 670, info["points"])
        broken = tmp_path / "broken.clf"
        broken.write_text("ODOM 0 0 0 0 0 0 1 h 1\nFLASER 2 1.0 x 0 0 0 0 0 0 2 h 2\n")
        outcome = mapctl.main("import", str(broken))
        assert outcome.code == EXIT_USAGE
        assert f"{broken}:2: FLASER: could not convert string to float: 'x'" in outcome.err

    def test_a_scan_matched_log_gives_a_grid_without_the_odometrys_smear(
        self, mapctl: Mapctl, tmp_path: Path
    ) -> None:
        mapctl("import", str(LOG), "--mission", "raw")
        matched = mapctl.json("import", str(LOG), "--mission", "matched", "--scan-match")
        (mission,) = matched["missions"]
        assert mission["scan_match"]["keyframes"] > 100
        assert mission["scan_match"]["largest"] > 5.0  # the head's odometry drifts that far

        raw = mapctl.json("grid", "-m", "raw", "-o", str(tmp_path / "raw.yaml"))
        fixed = mapctl.json("grid", "-m", "matched", "-o", str(tmp_path / "matched.yaml"))

        # The same rays, cast from poses that keep the walls in place, sweep far
        # less floor: the smear of drifting rays over the rooms is gone.
        assert fixed["cells"]["free"] < 0.7 * raw["cells"]["free"]
        assert "scans matched" in mapctl("import", str(LOG), "--mission", "again", "--scan-match")
        refused = mapctl.main("import", str(INTEL), "--scan-match")
        assert refused.code == EXIT_USAGE
        assert "--scan-match applies to laser logs" in refused.err

    def test_a_point_cloud_with_and_without_downsampling(self, mapctl: Mapctl) -> None:
        full = mapctl.json("import", str(ROOM), "--voxel", "0", "--mission", "full")
        thin = mapctl.json("import", str(ROOM), "--robot", "pcl")
        assert full["points"] == 112_586
        assert 0 < thin["points"] < full["points"]
        assert set(thin["missions"][0]["chunks"]) == {"missions", "pointclouds"}

    def test_human_output_names_missions_and_speed(self, mapctl: Mapctl) -> None:
        out = mapctl("import", str(INTEL))
        assert "intel" in out
        assert "elements/s" in out

    def test_a_malformed_line_exits_2_naming_it_and_commits_nothing(
        self, mapctl: Mapctl, tmp_path: Path
    ) -> None:
        lines = INTEL.read_text().splitlines(keepends=True)
        lines[1999] = "VERTEX_SE2 1999 1.0 oops 0.0\n"
        broken = tmp_path / "broken.g2o"
        broken.write_text("".join(lines))

        outcome = mapctl.main("import", str(broken))

        assert outcome.code == EXIT_USAGE
        assert outcome.err_lines == [
            f"error: {broken}:2000: VERTEX_SE2: could not convert string to float: 'oops'"
        ]
        assert mapctl.json("log") == []
        assert mapctl.json("chunk", "list") == {"chunks": []}

    def test_a_malformed_cloud_names_its_line(self, mapctl: Mapctl, tmp_path: Path) -> None:
        bad = tmp_path / "bad.ply"
        bad.write_text(
            "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
            "property float z\nend_header\n1 2 3\n4 5\n"
        )
        outcome = mapctl.main("import", str(bad))
        assert outcome.code == EXIT_USAGE
        assert f"{bad}:9: expected 3 values, found 2" in outcome.err

    def test_usage_errors(self, intel: Mapctl, tmp_path: Path) -> None:
        (tmp_path / "map.txt").write_text("VERTEX_SE2 0 0 0 0\n")
        unknown = intel.main("import", str(tmp_path / "map.txt"))
        assert unknown.code == EXIT_USAGE
        assert "pass --format" in unknown.err
        again = intel.main("import", str(INTEL))
        assert again.code == EXIT_USAGE
        assert "mission 'intel' exists already; pass another name" in again.err
        voxel = intel.main("import", str(INTEL), "--mission", "x", "--voxel", "1")
        assert voxel.code == EXIT_USAGE
        assert "--voxel applies to point clouds" in voxel.err
        assert intel.main("import", str(tmp_path / "missing.g2o")).code == EXIT_USAGE

    def test_format_overrides_the_extension(self, mapctl: Mapctl, tmp_path: Path) -> None:
        renamed = tmp_path / "intel.txt"
        renamed.write_bytes(INTEL.read_bytes())
        info = mapctl.json("import", str(renamed), "--format", "g2o")
        assert info["missions"][0]["name"] == "intel"


class TestMissionsAndExport:
    def test_missions_json_shape(self, intel: Mapctl) -> None:
        intel("import", str(ROOM), "--robot", "pcl")
        me = Repository.find(intel.repo).config.peer_id

        listed = intel.json("missions")

        holders = [{"id": me, "name": "bench", "address": ""}]
        assert [m["name"] for m in listed["missions"]] == ["intel", "room_scan1"]
        graph, scan = listed["missions"]
        assert {k: graph[k] for k in ("robot", "kind", "vertices", "edges", "points")} == {
            "robot": "hahnel",
            "kind": "graph",
            "vertices": 1_728,
            "edges": 2_512,
            "points": 0,
        }
        assert graph["bbox"] == pytest.approx([-9.53713, -22.4756, 0.0, 15.8719, 3.37798, 0.0])
        assert (graph["holders"], graph["held"]) == (holders, True)
        assert (scan["kind"], scan["robot"], scan["vertices"]) == ("cloud", "pcl", 0)
        assert scan["points"] > 10_000
        assert "room_scan1" in intel("missions")

    def test_missions_of_the_swarm_need_a_running_peer(self, intel: Mapctl) -> None:
        outcome = intel.main("missions", "--swarm")
        assert outcome.code == EXIT_NETWORK
        assert "mapctl peer start" in outcome.err

    def test_export_then_import_again_gives_the_same_counts(
        self, intel: Mapctl, tmp_path: Path
    ) -> None:
        out = tmp_path / "intel-out.g2o"
        info = intel.json("export", "intel", "-o", str(out))
        assert (info["format"], info["vertices"], info["edges"]) == ("g2o", 1_728, 2_512)
        intel("import", str(out), "--mission", "intel-again")
        counts = {
            m["name"]: (m["vertices"], m["edges"]) for m in intel.json("missions")["missions"]
        }
        assert counts == {"intel": (1_728, 2_512), "intel-again": (1_728, 2_512)}

    def test_a_cloud_exports_to_ply(self, mapctl: Mapctl, tmp_path: Path) -> None:
        mapctl("import", str(ROOM), "--voxel", "0")
        out = tmp_path / "room.ply"
        assert "112586 points" in mapctl("export", "room_scan1", "-o", str(out))
        assert out.read_bytes().startswith(b"ply\n")

    def test_a_trajectory_by_extension_or_format(self, intel: Mapctl, tmp_path: Path) -> None:
        said = intel("export", "intel", "-o", str(tmp_path / "intel.tum"))
        assert "1728 poses (no timestamps: the index is the time)" in said
        outcome = intel.main("export", "intel", "-o", str(tmp_path / "intel.txt"))
        assert outcome.code == EXIT_USAGE
        assert "pass --format tum or --format kitti" in outcome.err
        info = intel.json("export", "intel", "-o", str(tmp_path / "intel.txt"), "--format", "kitti")
        assert (info["format"], info["poses"], info["time"]) == ("kitti", 1_728, "index")
        assert len((tmp_path / "intel.txt").read_text().splitlines()[0].split()) == 12

    def test_export_of_an_unknown_mission_exits_2(self, intel: Mapctl, tmp_path: Path) -> None:
        outcome = intel.main("export", "nope", "-o", str(tmp_path / "x.g2o"))
        assert outcome.code == EXIT_USAGE
        assert "no mission 'nope' here" in outcome.err


class TestPlot:
    def test_graphs_with_a_query_box_of_negative_coordinates(
        self, intel: Mapctl, tmp_path: Path
    ) -> None:
        out = tmp_path / "map.png"
        info = intel.json("plot", "--bbox", "-5", "-10", "-1", "5", "0", "1", "-o", str(out))
        assert info == {
            "frame": "mission",
            "path": str(out),
            "renderer": "matplotlib",
            "up": "z",
            "missions": ["intel"],
            "bbox": [-5.0, -10.0, -1.0, 5.0, 0.0, 1.0],
        }
        assert out.read_bytes().startswith(PNG)

    def test_a_cloud_is_drawn_headless(self, mapctl: Mapctl, tmp_path: Path) -> None:
        mapctl("import", str(ROOM))
        out = tmp_path / "room.png"
        text = mapctl("plot", "-m", "room_scan1", "-o", str(out))
        assert "seen from above along z" in text
        assert out.read_bytes().startswith(PNG)

    def test_missions_outside_the_box_are_left_out(self, intel: Mapctl, tmp_path: Path) -> None:
        intel("import", str(TUNNELS))
        box = ["-230", "-50", "-50", "-160", "50", "300"]  # far down x: robots 5 and 6 only
        info = intel.json("plot", "--bbox", *box, "-o", str(tmp_path / "t.png"))
        assert info["missions"] == ["robot5", "robot6"]

    def test_zoom_and_title(self, intel: Mapctl, tmp_path: Path) -> None:
        out = tmp_path / "zoom.png"
        box = ["-5", "-10", "-1", "5", "0", "1"]
        info = intel.json("plot", "--bbox", *box, "--zoom", "--title", "a close-up", "-o", str(out))
        assert (info["missions"], info["renderer"]) == (["intel"], "matplotlib")
        assert out.read_bytes().startswith(PNG)
        alone = intel.main("plot", "--zoom", "-o", str(tmp_path / "x.png"))
        assert alone.code == EXIT_USAGE
        assert "zoom needs a box" in alone.err

    def test_nothing_to_draw_and_unknown_missions_exit_2(
        self, mapctl: Mapctl, tmp_path: Path
    ) -> None:
        empty = mapctl.main("plot", "-o", str(tmp_path / "x.png"))
        assert empty.code == EXIT_USAGE
        assert "import one with `mapctl import`" in empty.err
        unknown = mapctl.main("plot", "-m", "nope", "-o", str(tmp_path / "x.png"))
        assert unknown.code == EXIT_USAGE
        assert "no mission 'nope' here" in unknown.err


class TestThroughTheDaemon:
    async def test_import_missions_export_and_plot_run_in_the_peer(
        self, daemon: InProcessDaemon, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
    ) -> None:
        monkeypatch.chdir(tmp_path)  # relative paths are the caller's, not the daemon's
        (tmp_path / "maps").mkdir()
        (tmp_path / "maps" / "intel.g2o").write_bytes(INTEL.read_bytes())

        imported = await daemon.json("import", "maps/intel.g2o")
        listed = await daemon.json("missions", "--swarm")
        exported = await daemon.json("export", "intel", "-o", "intel-out.g2o")
        drawn = await daemon.json("plot", "-o", "intel.png")
        await daemon.json("import", str(LOG))
        grid = await daemon.json("grid", "-o", "head.yaml", "-m", "intel-head")  # in a process

        record = daemon.record
        assert record is not None
        assert imported["path"] == str(tmp_path / "maps" / "intel.g2o")
        (mission,) = listed["missions"]
        assert mission["holders"] == [{"id": record.id, "name": "bench", "address": record.address}]
        assert exported["path"] == str(tmp_path / "intel-out.g2o")
        assert (tmp_path / "intel-out.g2o").read_text().startswith("VERTEX_SE2 0 ")
        assert drawn["path"] == str(tmp_path / "intel.png")
        assert (tmp_path / "intel.png").read_bytes().startswith(PNG)
        assert (grid["path"], grid["scans"]) == (str(tmp_path / "head.yaml"), 671)
        assert (tmp_path / "head.pgm").read_bytes().startswith(b"P5\n")


class TestGrid:
    def test_a_laser_log_becomes_a_nav2_map(self, mapctl: Mapctl, tmp_path: Path) -> None:
        mapctl("import", str(LOG))
        target = tmp_path / "maps" / "head.yaml"
        target.parent.mkdir()
        box = ("--bbox", "-5", "-5", "0", "5", "4", "0", "--resolution", "0.1")

        info = mapctl.json("grid", "-o", str(target), *box)

        assert (info["width"], info["height"], info["origin"]) == (100, 90, [-5.0, -5.0, 0.0])
        assert (info["missions"], info["scans"], info["frame"]) == (["intel-head"], 671, "mission")
        assert info["image"] == str(target.with_suffix(".pgm"))
        assert sum(info["cells"].values()) == 100 * 90
        assert "image: head.pgm\nmode: trinary\nresolution: 0.1\n" in target.read_text()
        pgm = target.with_suffix(".pgm").read_bytes()
        assert pgm.startswith(b"P5\n")
        assert len(pgm.split(b"\n", 4)[4]) == 100 * 90
        said = mapctl("grid", "-o", str(tmp_path / "all.yaml"))
        assert said.startswith(f"wrote {tmp_path / 'all.yaml'} and all.pgm: 657 x 505 cells")

    def test_usage_errors(self, intel: Mapctl, tmp_path: Path) -> None:
        target = str(tmp_path / "map.yaml")
        before = {  # the Intel graph alone: no scans
            "no mission with laser scans or an occupancy grid here; import a CARMEN log": (),
            "no laser scans in 'intel'": ("-m", "intel"),
        }
        after = {
            "no mission 'nope' here": ("-m", "nope"),
            "grid of 65451 x 50300 cells at 0.0005 m is larger than 8192 x 8192": (
                *("-m", "intel-head", "--resolution", "0.0005"),
            ),
            "mission 'intel-head' has no place in the world frame yet": (
                *("-m", "intel-head", "--frame", "world"),
            ),
        }
        for cases in (before, after):
            if cases is after:
                intel("import", str(LOG))
            for message, args in cases.items():
                outcome = intel.main("grid", "-o", target, *args)
                assert outcome.code == EXIT_USAGE, args
                assert message in outcome.err, outcome.err
        pgm = intel.main("grid", "-o", str(tmp_path / "map.pgm"))
        assert "name the .yaml file, not 'map.pgm'" in pgm.err
        assert not (tmp_path / "map.yaml").exists()


class TestMissionRules:
    def test_a_second_vertex_100_set_by_hand_exits_2_naming_both(self, intel: Mapctl) -> None:
        """Issue 15: `set` stages it; the commit refuses it and writes nothing."""
        chunk = intel.json("missions")["missions"][0]["tiles"][-1]["vertices"]
        bogus = '{"mission": "intel", "index": 100, "pose": {"x": 9.0, "qw": 1.0}}'
        added = intel.json("set", "vertices", bogus, "--chunk", chunk)["id"]

        outcome = intel.main("commit", "-m", "a bogus pose")

        assert outcome.code == EXIT_USAGE
        assert "mission 'intel' would have vertex 100 twice" in outcome.err
        assert added in outcome.err
        assert intel.json("missions")["missions"][0]["vertices"] == 1_728
