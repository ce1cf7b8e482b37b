"""`mapctl grid` and `mapctl export` writing nav2 maps (issue 17 §4) on real
repositories: a large map cut into tiles, one mission's grid exported as .yaml,
stored grids in the world frame and grids whose origin is rotated."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tests.cli.conftest import Mapctl
from tests.unit.nav2_maps import put_back, read_pgm

SAMPLES = Path(__file__).resolve().parents[2] / "sample_maps"
LOG = SAMPLES / "laser_logs" / "intel-head.clf.bz2"
INTEL = SAMPLES / "pose_graphs" / "intel.g2o"
EXIT_USAGE = 2


class TestTiles:
    def test_tiles_put_back_together_are_the_single_map(
        self, mapctl: Mapctl, tmp_path: Path
    ) -> None:
        mapctl("import", str(LOG))
        whole = mapctl.json("grid", "-o", str(tmp_path / "head.yaml"))
        info = mapctl.json("grid", "-o", str(tmp_path / "big.yaml"), "--tile", "128")

        assert (whole["tile"], whole["tiles"], whole["skipped"]) == (None, [], 0)
        assert (info["tile"], info["image"]) == (128, None)
        assert info["path"] == str(tmp_path / "big.tiles.yaml")
        assert (info["width"], info["height"]) == (whole["width"], whole["height"]) == (657, 505)
        assert info["cells"] == whole["cells"]
        # 6 x 4 tiles of 128 cells (the last column and row narrower), the empty ones left out
        assert len(info["tiles"]) + info["skipped"] == 6 * 4
        assert info["skipped"] > 0
        first = info["tiles"][0]
        assert first["path"] == str(tmp_path / f"big_r{first['row']}_c{first['col']}.yaml")
        listed, cells = put_back(tmp_path / "big.tiles.yaml")
        assert listed["origin"] == whole["origin"]
        assert np.array_equal(cells, read_pgm(tmp_path / "head.pgm"))
        assert not (tmp_path / "big.yaml").exists()

        said = mapctl("grid", "-o", str(tmp_path / "big.yaml"), "--tile", "128")
        assert said.startswith(
            f"wrote {len(info['tiles'])} tile(s) of up to 128 x 128 cells, {info['skipped']} "
            f"all unknown left out, listed in {tmp_path / 'big.tiles.yaml'}: 657 x 505 cells"
        )
        zero = mapctl.main("grid", "-o", str(tmp_path / "x.yaml"), "--tile", "0")
        assert zero.code == EXIT_USAGE


class TestExport:
    def test_a_laser_mission_exports_as_its_grid(self, mapctl: Mapctl, tmp_path: Path) -> None:
        mapctl("import", str(LOG))
        grid = mapctl.json("grid", "-m", "intel-head", "-o", str(tmp_path / "grid.yaml"))
        info = mapctl.json("export", "intel-head", "-o", str(tmp_path / "head.yaml"))

        assert info == {
            "mission": "intel-head",
            "path": str(tmp_path / "head.yaml"),
            "format": "grid",
            "frame": "mission",
            "image": str(tmp_path / "head.pgm"),
            **{k: grid[k] for k in ("width", "height", "resolution", "origin", "cells")},
            "scans": 671,
        }
        assert np.array_equal(read_pgm(tmp_path / "head.pgm"), read_pgm(tmp_path / "grid.pgm"))
        yaml = (tmp_path / "head.yaml").read_text()
        assert yaml == (tmp_path / "grid.yaml").read_text().replace("grid.pgm", "head.pgm")

        said = mapctl("export", "intel-head", "-o", str(tmp_path / "map.yml"), "--format", "grid")
        assert said.startswith(
            f"wrote mission intel-head to {tmp_path / 'map.yml'}: a nav2 map of 657 x 505 cells "
            "of 0.05 m, image map.pgm (1640 occupied"
        )
        pgm = mapctl.main("export", "intel-head", "-o", str(tmp_path / "x.pgm"), "--format", "grid")
        assert pgm.code == EXIT_USAGE
        assert "name the .yaml file, not 'x.pgm'" in pgm.err

    def test_a_graph_without_scans_has_no_grid(self, mapctl: Mapctl, tmp_path: Path) -> None:
        mapctl("import", str(INTEL))
        outcome = mapctl.main("export", "intel", "-o", str(tmp_path / "intel.yaml"))
        assert outcome.code == EXIT_USAGE
        assert "no laser scans in 'intel'" in outcome.err
        assert not (tmp_path / "intel.yaml").exists()
