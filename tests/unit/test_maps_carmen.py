"""CARMEN laser logs (mapapi.maps.carmen, laser): the reader on the real Intel
log's first 2,000 lines (sample_maps/laser_logs), its errors by line, and the
import of a laser mission into a peer: poses, odometry edges, one point block
per scan naming its vertex."""

from __future__ import annotations

import bz2
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from mapapi import Peer
from mapapi.app import memory_peer
from mapapi.core.errors import UsageError
from mapapi.core.ids import ItemId
from mapapi.maps import EdgeKind, MapImportError, import_missions, list_missions, load_graph
from mapapi.maps.carmen import (
    MAX_RANGE,
    Odometry,
    Scan,
    log_name,
    read_carmen,
    read_records,
    relative_se2,
)
from mapapi.maps.cloud import block_points
from mapapi.maps.laser import LaserMission, beam_angles, project_scan
from mapapi.maps.schema import CLOUDS
from mapapi.maps.se3 import from_se2, yaw
from mapapi.maps.source import detect_format, read_source

SAMPLES = Path(__file__).resolve().parents[2] / "sample_maps"
LOG = SAMPLES / "laser_logs" / "intel-head.clf.bz2"
SCANS, ODOMS_BEFORE_FIRST_SCAN = 671, 1


def _lines() -> list[str]:
    with bz2.open(LOG, "rt", encoding="ascii") as log:
        return log.readlines()


def _log(tmp_path: Path, text: str, name: str = "tiny.clf") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="ascii")
    return path


RANGES = " ".join(["1.0"] * 4)


class TestReader:
    def test_the_intel_head_is_a_trajectory_of_its_scans(self) -> None:
        records = list(read_records(_lines()))
        scans = [r for r in records if isinstance(r, Scan)]
        assert len(scans) == SCANS
        assert sum(isinstance(r, Odometry) for r in records) == ODOMS_BEFORE_FIRST_SCAN

        laser = read_carmen(LOG, robot="hahnel")

        assert (laser.name, laser.robot, laser.frame, laser.planar) == (
            "intel-head",
            "hahnel",
            "intel-head/odom",
            True,
        )
        assert len(laser.vertices) == SCANS
        assert len(laser.edges) == SCANS - 1
        assert all(e.kind is EdgeKind.ODOMETRY for e in laser.edges)
        for index, scan in enumerate(scans):
            assert laser.vertices[index] == from_se2(*scan.odometry)
            assert laser.timestamps[index] == scan.timestamp
            assert laser.origins[index].line == scan.line
        returns = sum(int(((s.ranges > 0) & (s.ranges < MAX_RANGE)).sum()) for s in scans)
        assert laser.point_count() == returns > 100_000
        box = laser.bbox()
        assert box is not None
        assert (box.zmin, box.zmax) == (0.0, 0.0)

    def test_an_edge_is_the_relative_pose_of_consecutive_scans(self) -> None:
        laser = read_carmen(LOG)
        for edge in laser.edges[:50]:
            (_, i), (_, j) = edge.source, edge.target
            assert j == i + 1
            a, b = laser.vertices[i], laser.vertices[j]
            dx, dy, dtheta = relative_se2((a[0], a[1], yaw(a)), (b[0], b[1], yaw(b)))
            assert edge.relative[:2] == pytest.approx((dx, dy), abs=1e-12)
            assert yaw(edge.relative) == pytest.approx(dtheta, abs=1e-12)

    def test_a_scan_is_projected_from_the_laser_pose(self) -> None:
        angles = beam_angles(4)
        assert angles.tolist() == pytest.approx([-math.pi / 2, -math.pi / 4, 0.0, math.pi / 4])
        assert beam_angles(361)[[0, -1]].tolist() == pytest.approx([-math.pi / 2, math.pi / 2])
        ranges = np.array([1.0, 0.0, 2.0, 81.83])  # 0 and 81.83: no return
        points = project_scan(ranges, angles, (1.0, 2.0, math.pi / 2), MAX_RANGE)
        assert points.dtype == np.float32
        assert np.allclose(points, [[2.0, 2.0, 0.0], [1.0, 4.0, 0.0]], atol=1e-6)

    def test_a_log_without_scans_is_the_trajectory_of_its_odometry(self, tmp_path: Path) -> None:
        path = _log(tmp_path, "PARAM a 1\nODOM 0 0 0 0 0 0 5.0 h 0\nODOM 1 0 0 0 0 0 6.0 h 1\n")
        laser = read_carmen(path, mission="odo")
        assert (len(laser.vertices), len(laser.edges), laser.scans) == (2, 1, {})
        assert laser.timestamps == {0: 5.0, 1: 6.0}

    @pytest.mark.parametrize(
        ("text", "line", "says"),
        [
            (
                f"FLASER 4 {RANGES} 0 0 0 0 0 0 1 h 1\nFLASER 4 1 oops 1 1 0 0 0 0 0 0 2\n",
                2,
                "oops",
            ),
            ("# c\nFLASER 4 1 1 0 0 0 0 1 h 1\n", 2, "4 ranges need 12 values"),
            (f"FLASER 4 {RANGES} 0 nan 0 0 0 0 1 h 1\n", 1, "not a finite number"),
            ("ODOM 0 0 0 0 0\n", 1, "ODOM: expected x y theta"),
            ("FLASER -3 1\n", 1, "FLASER: 0 ranges need 8"),
        ],
    )
    def test_a_malformed_record_names_its_line(
        self, tmp_path: Path, text: str, line: int, says: str
    ) -> None:
        path = _log(tmp_path, text)
        with pytest.raises(MapImportError, match=says) as caught:
            read_carmen(path)
        assert caught.value.line == line
        assert str(caught.value).startswith(f"{path}:{line}: ")

    def test_a_log_with_no_trajectory_is_refused(self, tmp_path: Path) -> None:
        with pytest.raises(MapImportError, match="no FLASER or ODOM record"):
            read_carmen(_log(tmp_path, "PARAM a 1\n"))

    def test_the_format_follows_from_the_name(self, tmp_path: Path) -> None:
        assert detect_format("intel.clf") == detect_format(LOG) == "carmen"
        assert log_name(LOG) == "intel-head"
        with pytest.raises(UsageError, match="pass --format"):
            detect_format("graph.g2o.bz2")
        path = _log(tmp_path, f"FLASER 4 {RANGES} 0 0 0 0 0 0 1 h 1\n", "scan.log")
        (laser,) = read_source(path, "carmen", mission="m")
        assert isinstance(laser, LaserMission)
        assert laser.name == "m"


class TestImport:
    async def test_a_laser_mission_stores_a_block_per_scan_naming_its_vertex(self) -> None:
        peer = memory_peer()
        laser = read_carmen(LOG)

        (result,) = await import_missions(peer, [laser])

        assert (result.vertices, result.edges) == (SCANS, SCANS - 1)
        assert result.points == laser.point_count()
        assert set(result.chunks) == {"missions", "frames", CLOUDS}
        blocks = list((await _items(peer, CLOUDS)).values())
        assert len(blocks) == len(laser.scans)
        for block in blocks:
            assert block.HasField("vertex")
            assert np.array_equal(block_points(block), laser.scans[block.vertex])
        stored = await load_graph(peer, "intel-head")
        assert stored.timestamps == laser.timestamps
        assert stored.vertices == laser.vertices
        (info,) = await list_missions(peer)
        assert (info.kind, info.vertices, info.points) == ("graph", SCANS, laser.point_count())
        await peer.close()


async def _items(peer: Peer, table: str) -> dict[ItemId, Any]:
    """Every row of `table` the peer holds now."""
    tx = peer.begin()
    try:
        return await tx.items(table)
    finally:
        tx.abort()
