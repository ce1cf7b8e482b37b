"""Point clouds (mapapi.maps.cloud, cloud_file): blocks, PLY/PCD reading with
errors that name the line, downsampling, import into a peer and export to PLY."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mapapi import Peer
from mapapi.core.errors import UsageError
from mapapi.lookup.spatial import BBox
from mapapi.maps import CLOUDS, MISSIONS, MapImportError, PointCloud, import_cloud, load_cloud
from mapapi.maps.cloud import (
    BLOCK_POINTS,
    as_points,
    block_points,
    block_to_pb,
    cloud_blocks,
    points_box,
    split_blocks,
)
from mapapi.maps.cloud_file import read_cloud, write_cloud

SAMPLES = Path(__file__).resolve().parents[2] / "sample_maps"
ROOM = SAMPLES / "point_clouds" / "room_scan1.pcd"
ROOM_POINTS = 112_586  # sample_maps/README.md


def as_set(points: np.ndarray) -> np.ndarray:
    """The rows of `points`, sorted: a cloud is a set, its order is not kept."""
    points = np.ascontiguousarray(points, dtype=np.float32)
    return np.sort(points.view([("x", "f4"), ("y", "f4"), ("z", "f4")]).ravel())


def random_points(n: int, seed: int = 3) -> np.ndarray:
    return as_points(np.random.default_rng(seed).uniform(-20, 20, size=(n, 3)))


def ascii_ply(rows: list[str], count: int | None = None) -> str:
    header = [
        "ply",
        "format ascii 1.0",
        "comment written by a test",
        f"element vertex {len(rows) if count is None else count}",
        "property float x",
        "property float y",
        "property float z",
        "property uchar intensity",
        "end_header",
    ]
    return "\n".join(header + rows) + "\n"


def ascii_pcd(rows: list[str], count: int | None = None) -> str:
    n = len(rows) if count is None else count
    header = [
        "# .PCD v0.7 - Point Cloud Data file format",
        "VERSION 0.7",
        "FIELDS intensity x y z",
        "SIZE 4 4 4 4",
        "TYPE F F F F",
        "COUNT 1 1 1 1",
        f"WIDTH {n}",
        "HEIGHT 1",
        "VIEWPOINT 0 0 0 1 0 0 0",
        f"POINTS {n}",
        "DATA ascii",
    ]
    return "\n".join(header + rows) + "\n"


class TestBlocks:
    def test_blocks_hold_every_point_once_with_tight_boxes(self) -> None:
        points = random_points(10_000)
        groups = split_blocks(points, 1_000)
        assert all(500 <= len(g) <= 1_000 for g in groups)
        assert np.array_equal(as_set(np.concatenate(groups)), as_set(points))
        # k-d leaves do not overlap: their boxes add up to no more than the cloud's
        # (blocks cut in input order would each span nearly the whole cube)
        volume = sum(float(np.prod(g.max(axis=0) - g.min(axis=0))) for g in groups)
        assert volume <= 40**3

    def test_a_block_round_trips_bit_for_bit(self) -> None:
        points = random_points(3_000)
        block = block_to_pb("m", points)
        assert (block.mission, block.count) == ("m", 3_000)
        assert np.array_equal(block_points(block), points)
        assert BBox(
            block.bbox.xmin, block.bbox.ymin, block.bbox.zmin,
            block.bbox.xmax, block.bbox.ymax, block.bbox.zmax,
        ) == points_box(points)  # fmt: skip

    def test_repetitive_points_are_compressed(self) -> None:
        block = block_to_pb("m", as_points(np.zeros((1_000, 3))))
        assert block.compressed
        assert len(block.points) < 12 * 1_000 / 10
        assert np.array_equal(block_points(block), np.zeros((1_000, 3), np.float32))

    def test_a_block_with_the_wrong_byte_count_is_refused(self) -> None:
        block = block_to_pb("m", random_points(10))
        block.count = 11
        with pytest.raises(MapImportError, match="not 11 points"):
            block_points(block)

    def test_a_cloud_without_points_has_no_blocks_and_no_box(self) -> None:
        empty = PointCloud("m")
        assert cloud_blocks(empty) == []
        assert empty.bbox() is None


class TestReadCloud:
    def test_room_scan_downsampled_by_default(self) -> None:
        cloud = read_cloud(ROOM)
        assert cloud.name == "room_scan1"
        assert 10_000 < len(cloud.points) < ROOM_POINTS / 2
        box = cloud.bbox()
        assert box is not None  # README: x -13.8-15.4, y -6.5-8.0, z -1.4-1.7 m
        assert (round(box.xmin, 1), round(box.xmax, 1)) == (-13.8, 15.4)
        assert (round(box.ymin, 1), round(box.ymax, 1)) == (-6.5, 8.0)

    def test_voxel_zero_keeps_every_point_as_stored(self) -> None:
        cloud = read_cloud(ROOM, voxel=0)
        assert cloud.points.shape == (ROOM_POINTS, 3)
        assert cloud.points.dtype == np.float32

    def test_a_coarser_voxel_keeps_fewer_points(self) -> None:
        assert len(read_cloud(ROOM, voxel=0.5).points) < len(read_cloud(ROOM, voxel=0.1).points)

    def test_a_negative_voxel_is_refused(self) -> None:
        with pytest.raises(UsageError, match="voxel size"):
            read_cloud(ROOM, voxel=-1)

    @pytest.mark.parametrize("suffix", ["ply", "pcd"])
    def test_ascii_files_read_their_x_y_z_columns(self, tmp_path: Path, suffix: str) -> None:
        path = tmp_path / f"c.{suffix}"
        text = ascii_ply if suffix == "ply" else ascii_pcd
        rows = ["1 2 3 7", "4 5 6 7"] if suffix == "ply" else ["7 1 2 3", "7 4 5 6"]
        path.write_text(text(rows))
        cloud = read_cloud(path, voxel=0, mission="scan", robot="husky")
        assert (cloud.name, cloud.robot, cloud.frame) == ("scan", "husky", "scan/map")
        assert cloud.points.tolist() == [[1, 2, 3], [4, 5, 6]]

    def test_points_with_nan_are_dropped_and_counted(self, tmp_path: Path) -> None:
        path = tmp_path / "c.ply"
        path.write_text(ascii_ply(["1 2 3 0", "nan 5 6 0", "7 8 9 0"]))
        cloud = read_cloud(path, voxel=0)
        assert cloud.points.tolist() == [[1, 2, 3], [7, 8, 9]]
        assert cloud.dropped == 1

    def test_binary_ply_written_by_open3d_reads_back(self, tmp_path: Path) -> None:
        points = random_points(500)
        write_cloud(PointCloud("m", points=points), tmp_path / "c.ply")
        again = read_cloud(tmp_path / "c.ply", voxel=0)
        assert np.array_equal(as_set(again.points), as_set(points))


class TestMalformedCloudsNameTheLine:
    @pytest.mark.parametrize(
        ("name", "text", "line", "match"),
        [
            ("a.ply", "plyx\nformat ascii 1.0\n", 1, "not a PLY file"),
            ("b.ply", ascii_ply(["1 2 3 0"]).replace("property float z\n", ""), 4, "no field z"),
            ("c.ply", ascii_ply(["1 2 3 0", "4 five 6 0"]), 11, "are not all numbers"),
            ("d.ply", ascii_ply(["1 2 3 0", "4 5 0"]), 11, "expected 4 values, found 3"),
            ("e.ply", ascii_ply(["1 2 3 0"], count=3), 11, "ends after 1 of the 3 points"),
            ("f.ply", ascii_ply([]).replace("format ascii", "format morse"), 2, "format morse"),
            ("g.pcd", ascii_pcd(["0 1 2 3"]).replace("VIEWPOINT", "VIEWPINT"), 9, "VIEWPINT"),
            ("h.pcd", ascii_pcd(["0 1 2 3", "0 1 2 three"]), 13, "are not all numbers"),
            ("i.pcd", ascii_pcd(["0 1 2 3"]).replace("DATA ascii", "DATA zip"), 11, "DATA"),
            ("j.pcd", "VERSION 0.7\nFIELDS x y z\n", 3, "ends inside its header"),
        ],
    )
    def test_the_error_names_file_and_line(
        self, tmp_path: Path, name: str, text: str, line: int, match: str
    ) -> None:
        path = tmp_path / name
        path.write_text(text)
        with pytest.raises(MapImportError, match=match) as caught:
            read_cloud(path)
        assert caught.value.line == line
        assert str(caught.value).startswith(f"{path}:{line}: ")

    def test_a_truncated_binary_body_is_refused_at_its_point_count(self, tmp_path: Path) -> None:
        data = ROOM.read_bytes()
        cut = tmp_path / "cut.pcd"
        cut.write_bytes(data[: len(data) // 2])
        with pytest.raises(MapImportError, match="truncated or corrupt") as caught:
            read_cloud(cut)
        assert caught.value.line == 10  # POINTS 112586

    def test_an_unknown_format_is_a_usage_error(self, tmp_path: Path) -> None:
        (tmp_path / "c.xyz").write_text("1 2 3\n")
        with pytest.raises(UsageError, match="ply, pcd"):
            read_cloud(tmp_path / "c.xyz")


class TestImportCloud:
    async def test_one_commit_with_a_mission_row_and_point_blocks(self) -> None:
        peer = Peer.in_memory()
        cloud = read_cloud(ROOM, voxel=0, robot="pcl")

        result = await import_cloud(peer, cloud)

        assert len(peer.log()) == 1
        assert (result.mission, result.robot, result.points) == ("room_scan1", "pcl", ROOM_POINTS)
        assert set(result.chunks) == {MISSIONS, CLOUDS}
        assert result.bbox == cloud.bbox()
        tx = peer.begin()
        (row,) = (await tx.items(MISSIONS)).values()
        blocks = list((await tx.items(CLOUDS)).values())
        assert (row.name, row.robot, row.frame) == ("room_scan1", "pcl", "room_scan1/map")
        assert len(blocks) == 32  # halving 112,586 points 5 times gives leaves of <= 4,096
        assert max(b.count for b in blocks) <= BLOCK_POINTS
        assert sum(b.count for b in blocks) == ROOM_POINTS

    async def test_load_and_export_give_back_the_same_points(self, tmp_path: Path) -> None:
        peer = Peer.in_memory()
        cloud = read_cloud(ROOM, voxel=0)
        await import_cloud(peer, cloud)

        stored = await load_cloud(peer, "room_scan1")
        write_cloud(stored, tmp_path / "room.ply")
        again = read_cloud(tmp_path / "room.ply", voxel=0)

        assert np.array_equal(as_set(stored.points), as_set(cloud.points))
        assert np.array_equal(as_set(again.points), as_set(cloud.points))

    async def test_a_failure_while_staging_leaves_nothing(self) -> None:
        peer = Peer.in_memory()

        def explode(done: int, total: int) -> None:
            raise RuntimeError("stopped before the commit")

        with pytest.raises(RuntimeError, match="stopped"):
            await import_cloud(peer, read_cloud(ROOM), progress=explode)
        assert peer.log() == []
        assert peer.chunks() == []

    async def test_a_cloud_without_points_or_a_taken_name_is_refused(self) -> None:
        peer = Peer.in_memory()
        with pytest.raises(MapImportError, match="no points"):
            await import_cloud(peer, PointCloud("empty"))
        await import_cloud(peer, PointCloud("scan", points=random_points(10)))
        with pytest.raises(MapImportError, match="exists already"):
            await import_cloud(peer, PointCloud("scan", points=random_points(10)))
        assert len(peer.log()) == 1
