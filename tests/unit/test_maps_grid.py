"""Occupancy grids from laser scans (mapapi.maps.grid, grid_job): the casting
against a brute-force walk along each ray, a room seen from its middle, the
nav2 files, the size cap, the world frame, and the grid of the real Intel log's first 2,000
lines (sample_maps/laser_logs) checked against its scans."""

from __future__ import annotations

import itertools
import math
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from mapapi.app import memory_peer
from mapapi.core.errors import UsageError
from mapapi.lookup.spatial import BBox
from mapapi.maps import import_missions
from mapapi.maps.frames import MISSION, stage_frames
from mapapi.maps.grid import (
    FREE,
    MAX_SIDE,
    OCCUPIED,
    UNKNOWN,
    XY,
    GridSpec,
    OccupancyCounts,
    _count,
    grid_spec,
    write_nav2,
)
from mapapi.maps.grid_job import Rays, grid_missions, rays_at
from mapapi.maps.schema import CLOUDS, FRAMES
from mapapi.maps.source import read_source
from mapapi.maps.stored import GRAPH_READ, read_time
from mapapi.maps.world import WORLD, WorldFrame

SAMPLES = Path(__file__).resolve().parents[2] / "sample_maps"
LOG = SAMPLES / "laser_logs" / "intel-head.clf.bz2"
RESOLUTION = 0.05


def _cells(spec: GridSpec, at: XY) -> np.ndarray:
    """The flat cell (row 0 the top) of each point, by the grid's definition."""
    col = np.floor((at[:, 0] - spec.x0) / spec.resolution).astype(np.int64)
    up = np.floor((at[:, 1] - spec.y0) / spec.resolution).astype(np.int64)
    return (spec.height - 1 - up) * spec.width + col


def _walked(spec: GridSpec, origin: XY, end: XY) -> set[int]:
    """The cells a ray crosses, found by stepping along it a 2,000th of a cell
    at a time (a corner clipped by less than that is missed)."""
    steps = int(np.hypot(*(end - origin)) / spec.resolution * 2000) + 2
    t = np.linspace(0.0, 1.0, steps)[:, None]
    return {int(c) for c in np.unique(_cells(spec, origin + (end - origin) * t))}


def _crossed(spec: GridSpec, origin: XY, end: XY) -> set[int]:
    """The cells a ray crosses, exactly (in rationals), on a grid of 1 m cells at
    the origin: split the ray where it meets any line between cells, and take
    the cell of the middle of each piece."""
    (ox, oy), (ex, ey) = [[Fraction(float(v)) for v in p] for p in (origin, end)]
    cuts = {Fraction(0), Fraction(1)}
    for a, b in ((ox, ex), (oy, ey)):
        low, high = sorted((a, b))
        cuts |= {(line - a) / (b - a) for line in range(math.ceil(low), math.floor(high) + 1)}
    ts = sorted(c for c in cuts if 0 <= c <= 1)
    middles = [(t + u) / 2 for t, u in itertools.pairwise(ts)]
    return {
        (spec.height - 1 - math.floor(oy + m * (ey - oy))) * spec.width
        + math.floor(ox + m * (ex - ox))
        for m in middles
    }


class TestCasting:
    def test_a_ray_passes_the_cells_it_crosses_and_hits_its_last(self) -> None:
        spec = grid_spec(0.0, 0.0, 20.0, 20.0, 1.0)  # cells of 1 m: metres are cells
        rng = np.random.default_rng(17)
        for _ in range(300):
            origin, end = rng.uniform(0.0, 20.0, (2, 2))
            counts = OccupancyCounts(spec)
            counts.add_rays(origin[None], end[None])
            last = int(_cells(spec, end[None])[0])
            assert set(np.flatnonzero(counts.hits)) == {last}
            assert set(np.flatnonzero(counts.passes)) == _crossed(spec, origin, end) - {last}
            assert counts.passes.max() <= 1  # no cell twice

    def test_a_room_seen_from_its_middle(self) -> None:
        spec = grid_spec(-2.0, -2.0, 2.0, 2.0, 0.1)  # walls at +-1.55 m, mid-cell
        bearings = np.radians(np.arange(0.0, 360.0, 0.25))
        reach = 1.55 / np.maximum(np.abs(np.cos(bearings)), np.abs(np.sin(bearings)))
        ends = np.c_[reach * np.cos(bearings), reach * np.sin(bearings)]
        counts = OccupancyCounts(spec)
        counts.add_rays(np.zeros_like(ends), ends)
        image = counts.image()
        assert image.shape == (40, 40)
        centres = (np.arange(40) + 0.5) * 0.1 - 2.0
        x, y = np.meshgrid(centres, centres[::-1])  # row 0 the top
        edge = np.maximum(np.abs(x), np.abs(y))
        assert (image[edge < 1.5] == FREE).all()
        assert (image[edge > 1.6] == UNKNOWN).all()
        wall = image[(edge > 1.5) & (edge < 1.6)]
        assert (wall == OCCUPIED).mean() > 0.95

    def test_rays_outside_the_grid_cast_nothing(self) -> None:
        counts = OccupancyCounts(grid_spec(0.0, 0.0, 1.0, 1.0, 0.1))
        counts.add_rays(np.array([[5.0, 5.0]]), np.array([[6.0, 5.0]]))
        counts.add_rays(np.array([[-1.0, 0.55]]), np.array([[0.55, 0.55]]))  # enters it
        assert counts.hits.sum() == 1
        assert counts.passes.sum() == 5

    def test_both_ways_of_counting_agree(self) -> None:
        cells = np.random.default_rng(3).integers(0, 1000, 50)
        dense, sparse = np.zeros(100, np.int32), np.zeros(100_000, np.int32)
        _count(dense, cells % 100)
        _count(sparse, cells)
        assert dense.sum() == sparse.sum() == 50
        assert (np.bincount(cells, minlength=100_000) == sparse).all()


class TestSize:
    def test_the_grid_covers_the_box(self) -> None:
        spec = grid_spec(-1.0, 2.0, 3.02, 3.0, 0.05)
        assert (spec.width, spec.height, spec.x0, spec.y0) == (81, 20, -1.0, 2.0)

    def test_a_grid_too_large_names_its_size(self) -> None:
        with pytest.raises(UsageError, match=r"20000 x 100 cells at 0.005 m is larger than 8192"):
            grid_spec(0.0, 0.0, 100.0, 0.5, 0.005)
        assert grid_spec(0.0, 0.0, MAX_SIDE * 0.01, 1.0, 0.01).width == MAX_SIDE

    @pytest.mark.parametrize(("box", "resolution"), [((0, 0, 0, 1), 0.0), ((1, 0, 1, 1), 0.1)])
    def test_no_grid_of_nothing(self, box: tuple[float, ...], resolution: float) -> None:
        with pytest.raises(UsageError):
            grid_spec(*box, resolution)


def read_pgm(path: Path) -> np.ndarray:
    """A binary PGM (P5, one comment line at most) as rows of bytes."""
    data = path.read_bytes()
    lines = data.split(b"\n", 4)
    assert lines[0] == b"P5"
    assert lines[1].startswith(b"#")
    assert lines[3] == b"255"
    width, height = map(int, lines[2].split())
    pixels = np.frombuffer(lines[4], dtype=np.uint8)
    assert len(pixels) == width * height
    return pixels.reshape(height, width)


def test_the_nav2_files(tmp_path: Path) -> None:
    spec = GridSpec(-1.5, 2.0, 0.5, 3, 2)
    pixels = np.array([[0, 254, 205], [205, 205, 254]], dtype=np.uint8)
    image = write_nav2(pixels, spec, tmp_path / "map.yaml")
    assert image == tmp_path / "map.pgm"
    assert (read_pgm(image) == pixels).all()
    assert yaml.safe_load((tmp_path / "map.yaml").read_text()) == {
        "image": "map.pgm",
        "mode": "trinary",
        "resolution": 0.5,
        "origin": [-1.5, 2.0, 0.0],
        "negate": 0,
        "occupied_thresh": 0.65,
        "free_thresh": 0.196,  # nav2 reads 205 as 1 - 205/255 = 0.196 occupied: unknown
    }


class TestIntelHead:
    """The grid of the Intel log's first 671 scans, against the scans themselves."""

    @pytest.fixture(scope="class")
    @classmethod
    def cast(cls, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
        import asyncio

        target = tmp_path_factory.mktemp("grid") / "head.yaml"

        async def run() -> dict[str, Any]:
            peer = memory_peer()
            try:
                await import_missions(peer, read_source(LOG, robot="hahnel"))
                async with read_time(peer, ["intel-head"], (*GRAPH_READ, CLOUDS)) as at:
                    rays = rays_at(peer, at, "intel-head")
                    info = grid_missions(peer, at, ["intel-head"], target, None, RESOLUTION)
                    box = BBox(-5.0, -5.0, -1.0, 5.0, 4.0, 1.0)
                    boxed = grid_missions(
                        peer, at, ["intel-head"], target.with_name("box.yaml"), box, 0.1
                    )
            finally:
                await peer.close()
            return {"rays": rays, "info": info, "boxed": boxed, "target": target}

        return asyncio.run(run())

    def test_the_files_parse_and_match_the_box(self, cast: dict[str, Any]) -> None:
        meta = yaml.safe_load(cast["target"].with_name("box.yaml").read_text())
        image = read_pgm(cast["target"].with_name(meta["image"]))
        assert image.shape == (90, 100) == (cast["boxed"]["height"], cast["boxed"]["width"])
        assert meta["origin"] == [-5.0, -5.0, 0.0]
        assert meta["resolution"] == 0.1
        assert set(np.unique(image)) <= {OCCUPIED, FREE, UNKNOWN}

    def test_occupied_cells_are_where_scans_ended(self, cast: dict[str, Any]) -> None:
        spec, image, rays = self._grid(cast)
        occupied = np.flatnonzero(image == OCCUPIED)
        assert len(occupied) > 1000
        assert np.isin(occupied, _cells(spec, rays.ends)).all()

    def test_the_robots_poses_are_free(self, cast: dict[str, Any]) -> None:
        spec, image, rays = self._grid(cast)
        poses = np.unique(_cells(spec, np.unique(rays.origins, axis=0)))
        assert len(poses) > 300
        assert (image[poses] == FREE).all()

    def test_cells_along_the_rays_are_free(self, cast: dict[str, Any]) -> None:
        spec, image, rays = self._grid(cast)
        picked = np.random.default_rng(5).choice(len(rays.ends), 300, replace=False)
        seen = []
        for i in picked:
            last = int(_cells(spec, rays.ends[i : i + 1])[0])
            seen += [image[c] for c in _walked(spec, rays.origins[i], rays.ends[i]) - {last}]
        assert np.mean(np.array(seen) == FREE) > 0.98

    def test_what_it_says(self, cast: dict[str, Any]) -> None:
        info = cast["info"]
        assert (info["scans"], info["missions"], info["without_scans"]) == (671, ["intel-head"], [])
        assert info["rays"] == len(cast["rays"].ends)
        assert sum(info["cells"].values()) == info["width"] * info["height"]

    @staticmethod
    def _grid(cast: dict[str, Any]) -> tuple[GridSpec, np.ndarray, Rays]:
        info = cast["info"]
        x0, y0, _ = info["origin"]
        spec = GridSpec(x0, y0, info["resolution"], info["width"], info["height"])
        return spec, read_pgm(cast["target"].with_suffix(".pgm")).ravel(), cast["rays"]


async def test_in_the_world_frame_the_rays_move_with_the_missions_place() -> None:
    peer = memory_peer()
    try:
        (result,) = await import_missions(peer, read_source(LOG, robot="hahnel"))
        turn = (0.0, 0.0, math.sin(math.pi / 4), math.cos(math.pi / 4))  # 90° about z
        place = WorldFrame("intel-head", (10.0, -3.0, 0.0, *turn), (0.0,) * 21, "a", (), 0, "", "")
        tx = peer.begin()
        stage_frames(tx, [place], {}, {"intel-head": result.chunks[FRAMES]}, [])
        await tx.commit("place it")
        async with read_time(peer, ["intel-head"], (*GRAPH_READ, CLOUDS, FRAMES)) as at:
            own, world = (rays_at(peer, at, "intel-head", frame) for frame in (MISSION, WORLD))
    finally:
        await peer.close()
    rotate = np.array([[0.0, -1.0], [1.0, 0.0]])
    assert world.scans == own.scans == 671
    assert np.allclose(world.origins, own.origins @ rotate.T + [10.0, -3.0])
    assert np.allclose(world.ends, own.ends @ rotate.T + [10.0, -3.0])
