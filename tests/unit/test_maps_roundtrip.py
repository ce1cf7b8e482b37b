"""`export` is deterministic and faithful (issue 15): every sample map in
sample_maps/ is imported into a peer on a real repository and exported again.

- A g2o file comes back byte for byte, in its own record order and number
  formatting, except for what a pose graph does not hold: blank lines,
  comments (`#`) and `FIX` lines. Its normal form (`g2o_normal_form`) drops
  those; the shipped g2o files have none, so for them it is the file itself.
- A Kimera folder is CSV, which `export` does not write: each robot's mission
  exports as the g2o text its graph gives (`write_g2o` of the parsed graph),
  with vertices by index, then the edges in the order the files list them.
- A DGS folder (`<n>.g2o`, GTSAM Symbol keys) is a multi-robot set like a
  Kimera folder: each robot's mission exports as the g2o its graph gives.
- GTSAM landmark text is not g2o: its mission exports as g2o (`VERTEX_XY`,
  `EDGE_SE2_XY`), and that file comes back byte for byte.
- A point cloud is downsampled into blocks at import and the order of its
  points is not kept (DESIGN "Maps"): with `--voxel 0` the exported cloud
  holds exactly the source's points, and exporting twice gives the same bytes.
- A CARMEN laser log is no format `export` writes: its trajectory exports as
  TUM with the scans' times and odometry poses (read back with evo), and its
  scans as a cloud of the points they project to.
"""

from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np
import pytest
from evo.tools.file_interface import read_tum_trajectory_file

from mapapi import Peer
from mapapi.maps import read_kimera
from mapapi.maps.carmen import Scan, open_log, read_carmen, read_records
from mapapi.maps.cloud_file import read_cloud
from mapapi.maps.dgs import read_g2o_source, robot_files
from mapapi.maps.g2o import looks_planar, write_g2o
from mapapi.maps.operations import MapOperations
from mapapi.maps.source import detect_format

SAMPLES = Path(__file__).resolve().parents[2] / "sample_maps"
DGS_FOLDERS = sorted({p.parent for p in SAMPLES.rglob("*.g2o") if robot_files(p.parent)})
DGS_FILES = {p for folder in DGS_FOLDERS for p in robot_files(folder)}
G2O_FILES = sorted(set(SAMPLES.rglob("*.g2o")) - DGS_FILES)
GTSAM_FILES = sorted(p for p in SAMPLES.rglob("*.txt") if detect_format(p) == "gtsam-landmarks")
KIMERA_FOLDERS = sorted({p.parent.parent for p in SAMPLES.rglob("measurements.csv")})
CLOUD_FILES = sorted(p for e in ("*.pcd", "*.ply") for p in SAMPLES.rglob(e))
LOG_FILES = sorted(SAMPLES.rglob("*.clf.bz2"))
NOT_MAPS = {"README.md", "SHA256SUMS"}


def g2o_normal_form(text: str) -> str:
    """The g2o text a faithful export gives back: every record line as it was,
    without blank lines, comments and FIX lines, each ending in a line break."""
    kept = []
    for line in text.splitlines():
        tag = line.split()[0] if line.split() else ""
        if tag and not tag.startswith("#") and tag != "FIX":
            kept.append(line + "\n")
    return "".join(kept)


def _bytes(path: Path) -> bytes:
    return path.read_bytes()


@pytest.fixture
async def ops(make_peer) -> MapOperations:  # type: ignore[no-untyped-def]
    peer: Peer = await make_peer()
    return MapOperations(peer)


def test_every_sample_map_is_covered() -> None:
    """A map added to sample_maps/ must get a round trip here."""
    covered = set(G2O_FILES) | set(CLOUD_FILES) | set(LOG_FILES) | DGS_FILES | set(GTSAM_FILES)
    covered |= {p for folder in KIMERA_FOLDERS for p in folder.rglob("measurements.csv")}
    maps = {
        p
        for p in SAMPLES.rglob("*")
        if p.is_file() and p.name not in NOT_MAPS and not p.name.startswith("LICENSE")
    }
    assert maps == covered
    counts = (len(G2O_FILES), len(KIMERA_FOLDERS), len(CLOUD_FILES), len(DGS_FOLDERS))
    assert (*counts, len(GTSAM_FILES), len(LOG_FILES)) == (3, 1, 1, 1, 1, 1)


@pytest.mark.parametrize("source", G2O_FILES, ids=lambda p: p.name)
async def test_a_g2o_file_exports_byte_for_byte(
    ops: MapOperations, source: Path, tmp_path: Path
) -> None:
    await ops.imports.import_map(str(source))
    out = tmp_path / source.name

    await ops.export_map(source.stem, str(out))
    again = tmp_path / f"again-{source.name}"
    await ops.export_map(source.stem, str(again))

    text = _bytes(source)
    assert g2o_normal_form(text.decode()) == text.decode()  # the shipped files are
    assert out.read_bytes() == text
    assert again.read_bytes() == text


async def test_comments_blank_and_fix_lines_give_the_normal_form(
    ops: MapOperations, tmp_path: Path
) -> None:
    source = tmp_path / "commented.g2o"
    source.write_text(
        "# a comment\nVERTEX_SE2 0 0 0 0\n\nFIX 0\nVERTEX_SE2 1 1.50 0 0\n"
        "EDGE_SE2 0 1 1.5 0 0 1 0 0 1 0 1\nVERTEX_SE2 2 3 0 0"  # no final line break
    )
    await ops.imports.import_map(str(source))
    await ops.export_map("commented", str(tmp_path / "out.g2o"))
    assert (tmp_path / "out.g2o").read_text() == g2o_normal_form(source.read_text())


async def test_an_edited_record_is_written_from_its_values(
    ops: MapOperations, tmp_path: Path
) -> None:
    """A record keeps its number formatting while that writes its values exactly;
    else its values are written in their shortest exact form."""
    from mapapi.maps import VERTICES
    from mapapi.maps.schema import pose_to_pb
    from mapapi.maps.se3 import from_se2

    source = tmp_path / "small.g2o"
    source.write_text(
        "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1.50 0 0\nVERTEX_SE2 2 1.75 0 0\n"
        "EDGE_SE2 0 1 1.5 0 0 1 0 0 1 0 1\nEDGE_SE2 1 2 0.25 0 0 1 0 0 1 0 1\n"
    )
    await ops.imports.import_map(str(source))
    tx = ops.peer.begin()
    for index, x in ((1, 2.0), (2, 2.125)):  # 2.125 is not 2.12 or 2.13
        (item,) = await tx.find(VERTICES, "index", index)
        moved = await tx.get(VERTICES, item)
        assert moved is not None
        moved.pose.CopyFrom(pose_to_pb(from_se2(x, 0.0, 0.0)))
        tx.update(VERTICES, item, moved)
    await tx.commit()

    await ops.export_map("small", str(tmp_path / "out.g2o"))
    assert (tmp_path / "out.g2o").read_text().splitlines() == [
        "VERTEX_SE2 0 0 0 0",
        "VERTEX_SE2 1 2.00 0 0",
        "VERTEX_SE2 2 2.125 0.0 0.0",
        "EDGE_SE2 0 1 1.5 0 0 1 0 0 1 0 1",
        "EDGE_SE2 1 2 0.25 0 0 1 0 0 1 0 1",
    ]


SETS = [(f, "kimera-csv") for f in KIMERA_FOLDERS] + [(f, "g2o") for f in DGS_FOLDERS]


@pytest.mark.parametrize(("folder", "fmt"), SETS, ids=lambda p: getattr(p, "name", p))
async def test_a_multi_robot_set_exports_as_the_g2o_of_its_graphs(
    ops: MapOperations, folder: Path, fmt: str, tmp_path: Path
) -> None:
    assert detect_format(folder) == fmt
    await ops.imports.import_map(str(folder))
    graphs = read_kimera(folder) if fmt == "kimera-csv" else read_g2o_source(folder, None, None)
    for graph in graphs:
        expected = io.StringIO()
        write_g2o(graph, expected, planar=looks_planar(graph))
        out = tmp_path / f"{graph.name}.g2o"
        await ops.export_map(graph.name, str(out))
        assert out.read_text() == expected.getvalue(), graph.name


@pytest.mark.parametrize("source", GTSAM_FILES, ids=lambda p: p.name)
async def test_a_landmark_file_exports_as_g2o_that_comes_back_byte_for_byte(
    ops: MapOperations, source: Path, tmp_path: Path
) -> None:
    await ops.imports.import_map(str(source))
    out, again = tmp_path / "first.g2o", tmp_path / "again.g2o"
    await ops.export_map(source.stem, str(out))
    await ops.imports.import_map(str(out), mission="again")
    await ops.export_map("again", str(again))

    text = out.read_text()
    assert "VERTEX_XY " in text
    assert "EDGE_SE2_XY " in text
    assert again.read_bytes() == out.read_bytes()


@pytest.mark.parametrize("source", CLOUD_FILES, ids=lambda p: p.name)
async def test_a_cloud_exports_its_points_the_same_way_twice(
    ops: MapOperations, source: Path, tmp_path: Path
) -> None:
    await ops.imports.import_map(str(source), voxel=0)
    first, second = tmp_path / f"a{source.suffix}", tmp_path / f"b{source.suffix}"
    await ops.export_map(source.stem, str(first))
    await ops.export_map(source.stem, str(second))

    assert first.read_bytes() == second.read_bytes()
    exported = read_cloud(first, voxel=0).points
    original = read_cloud(source, voxel=0).points
    assert np.array_equal(np.unique(exported, axis=0), np.unique(original, axis=0))


@pytest.mark.parametrize("source", LOG_FILES, ids=lambda p: p.name)
async def test_a_laser_log_exports_its_trajectory_and_its_scans(
    ops: MapOperations, source: Path, tmp_path: Path
) -> None:
    info = await ops.imports.import_map(str(source))
    (mission,) = info["missions"]
    with open_log(source) as log:
        scans = [r for r in read_records(log) if isinstance(r, Scan)]

    exported = await ops.export_map(mission["name"], str(tmp_path / "log.tum"))

    assert (exported["poses"], exported["time"]) == (len(scans), "timestamp")
    read = read_tum_trajectory_file(tmp_path / "log.tum")
    assert read.timestamps.tolist() == [s.timestamp for s in scans]
    assert read.positions_xyz.tolist() == [[s.odometry[0], s.odometry[1], 0.0] for s in scans]
    yaws = [2 * math.atan2(q[3], q[0]) for q in read.orientations_quat_wxyz]
    assert yaws == pytest.approx([s.odometry[2] for s in scans], abs=1e-12)
    await ops.export_map(mission["name"], str(tmp_path / "scans.ply"))
    points = read_cloud(tmp_path / "scans.ply", voxel=0).points
    laser = read_carmen(source)
    projected = np.concatenate(list(laser.scans.values()))
    assert len(points) == mission["points"] == len(projected)
    assert np.array_equal(np.unique(points, axis=0), np.unique(projected, axis=0))
