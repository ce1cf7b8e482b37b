"""`mapctl align`, then `plot`, `export` in the world frame (issue 17 §1), on a
repository alone: the frames are a commit like any other."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mapapi.maps.alignment import pose_matrix
from tests.cli.conftest import Mapctl

pytest.importorskip("gtsam", reason="the registration extra (make test installs it)")
TUNNELS = Path(__file__).resolve().parents[2] / "sample_maps" / "kimera_multi_tunnels_8robots"
EXIT_USAGE = 2


def _poses(path: Path) -> np.ndarray:
    """The poses of a TUM file as 4x4 matrices."""
    rows = np.loadtxt(path)
    return np.stack([pose_matrix(tuple(r[1:])) for r in rows])


@pytest.fixture
def tunnels(mapctl: Mapctl) -> Mapctl:
    mapctl("import", str(TUNNELS))
    return mapctl


def test_align_commits_each_missions_place_and_world_reads_use_it(
    tunnels: Mapctl, tmp_path: Path
) -> None:
    done = tunnels.json("align", "-m", "robot1", "-m", "robot3", "--anchor", "robot3")

    assert [f["mission"] for f in done["frames"]] == ["robot1", "robot3"]
    assert done["frames"][1]["transform"] == pytest.approx([0, 0, 0, 0, 0, 0, 1], abs=1e-9)
    assert done["inliers"] > 0
    assert done["rms_after"]["metres"] < done["rms_before"]["metres"]
    assert tunnels.json("log")[0]["message"] == done["message"]

    mission, world = tmp_path / "m.tum", tmp_path / "w.tum"
    tunnels("export", "robot1", "-o", str(mission))
    info = tunnels.json("export", "robot1", "--frame", "world", "-o", str(world))
    assert info["frame"] == "world"
    place = pose_matrix(tuple(done["frames"][0]["transform"]))
    assert np.allclose(_poses(world), place @ _poses(mission), atol=1e-6)

    # the places lie at the missions' boxes moved to the world; a plain query skips them
    box = [str(v) for v in world_box_of(tunnels, "robot1")]
    found = tunnels.json("query-bbox", *box, "--frame", "world")["results"]
    assert {(r["table"], tuple(r["missions"])) for r in found} >= {("frames", ("robot1",))}
    plain = tunnels.json("query-bbox", *box)["results"]
    assert "frames" not in {r["table"] for r in plain}

    drawn = tunnels.json(
        "plot", "--frame", "world", "-m", "robot1", "-m", "robot3", "-o", str(tmp_path / "w.png")
    )
    assert (drawn["frame"], drawn["missions"]) == ("world", ["robot1", "robot3"])


def world_box_of(mapctl: Mapctl, mission: str) -> list[float]:
    """The mission's box in the world frame, as `missions --frame world` gives it."""
    listed = mapctl.json("missions", "--frame", "world")["missions"]
    (row,) = [m for m in listed if m["name"] == mission]
    assert row["aligned"] is True
    return list(row["bbox"])


def test_a_mission_never_aligned_has_no_place_in_the_world_frame(
    tunnels: Mapctl, tmp_path: Path
) -> None:
    outcome = tunnels.main("export", "robot0", "--frame", "world", "-o", str(tmp_path / "x.tum"))

    assert outcome.code == EXIT_USAGE
    assert "no place in the world frame yet; run `mapctl align`" in outcome.err
    assert not (tmp_path / "x.tum").exists()
