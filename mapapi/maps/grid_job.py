"""`mapctl grid`'s job: read laser missions' scans as rays and cast them into a
nav2 occupancy grid (`mapapi.maps.grid`), off the event loop (`jobs.run_job`).

A laser mission (`mapapi.maps.laser`) stores each scan as a point block that
names its vertex: the rays run from that vertex's position to each point.
Both are in the mission's frame; in the world frame both are moved by the
mission's place there (`frames.frame_at`), one rigid transform per mission,
as `export --frame world` moves poses. A scan keeps no record of its beams
that returned nothing, so no ray is cast for them.

Grid missions (a bag's `nav_msgs/OccupancyGrid`, `mapapi.maps.occupancy`) are
cast already: `write_stored_grids` composes their tiles at their own resolution
and writes their occupancy as nav2's pixels: cell for cell when the tiles lie
along the axes, else (an origin turned about z, or a mission's place in the
world frame, `grid_places`) resampled along them, nearest neighbour.
With a tile side, either is written as nav2 tiles (`mapapi.maps.map_tiles`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from mapapi.core.errors import UsageError
from mapapi.lookup.spatial import BBox
from mapapi.maps.alignment import pose_matrix
from mapapi.maps.cloud import block_points
from mapapi.maps.frames import MISSION, place_in_world
from mapapi.maps.grid import (
    FREE,
    OCCUPIED,
    UNKNOWN,
    XY,
    GridSpec,
    OccupancyCounts,
    grid_spec,
    write_nav2,
)
from mapapi.maps.map_tiles import MapTile, write_tiles
from mapapi.maps.occupancy import compose_tiles, nav2_pixels, tiles_box
from mapapi.maps.plane import Placement, planar_placement
from mapapi.maps.schema import CLOUDS, GRIDS, VERTICES
from mapapi.maps.stored import mission_row, rows_of

if TYPE_CHECKING:
    from mapapi.service.peer import Peer


@dataclass(frozen=True, slots=True)
class Rays:
    """A mission's scans as rays in one frame: ray i runs from `origins[i]` to
    `ends[i]` (x, y in metres); `scans` counts the scans they came from."""

    origins: XY
    ends: XY
    scans: int


def rays_at(peer: Peer, time: int, mission: str, frame: str = MISSION) -> Rays:
    """The rays of `mission`'s scans as of `time`, in `frame`.

    Raises:
        MapImportError: no such mission.
        UsageError: in the world frame, the mission was never aligned.
    """
    mission_row(peer, time, mission)
    where = {
        v.index: (v.pose.x, v.pose.y, v.pose.z) for v in rows_of(peer, time, VERTICES, mission)
    }
    blocks = [b for b in rows_of(peer, time, CLOUDS, mission) if b.HasField("vertex")]
    blocks = [b for b in blocks if b.vertex in where]  # a scan whose pose is not held here
    if not blocks:
        empty = np.zeros((0, 2))
        return Rays(empty, empty, 0)
    ends = np.concatenate([block_points(b) for b in blocks]).astype(np.float64)
    counts = [b.count for b in blocks]
    origins = np.repeat(np.array([where[b.vertex] for b in blocks]), counts, axis=0)
    if frame != MISSION:
        hint = "run `mapctl align`, or cast it in its own frame (--frame mission)"
        move = pose_matrix(place_in_world(peer, time, mission, hint).pose)
        origins, ends = (p @ move[:3, :3].T + move[:3, 3] for p in (origins, ends))
    return Rays(origins[:, :2], ends[:, :2], len(blocks))


def grid_missions(
    peer: Peer,
    time: int,
    missions: list[str],
    target: Path,
    box: BBox | None,
    resolution: float,
    frame: str = MISSION,
    tile: int | None = None,
) -> dict[str, object]:
    """Cast the scans of `missions` as of `time` into a grid of `resolution`
    over `box` (default: around every ray) in `frame`, and write it to the
    nav2 YAML `target` and the PGM beside it (with `tile`, as tiles of that
    many cells a side: `map_tiles`); what was written.

    Raises:
        UsageError: none of the missions has a laser scan, the grid would be
            too large (`grid.MAX_SIDE`), or in the world frame a mission was
            never aligned.
        MapImportError: no such mission.
    """
    found = {name: rays_at(peer, time, name, frame) for name in missions}
    cast = [name for name, rays in found.items() if rays.scans]
    if not cast:
        raise UsageError(
            f"no laser scans in {', '.join(map(repr, missions))}; a grid is cast from laser "
            "scans: import a CARMEN log (.clf)"
        )
    origins = np.concatenate([found[n].origins for n in cast])
    ends = np.concatenate([found[n].ends for n in cast])
    if box is None:
        both = np.concatenate([origins, ends])
        margin = resolution  # so the outermost returns are cells inside the grid
        xmin, ymin = both.min(axis=0) - margin
        xmax, ymax = both.max(axis=0) + margin
    else:
        xmin, ymin, xmax, ymax = box.xmin, box.ymin, box.xmax, box.ymax
    spec = grid_spec(float(xmin), float(ymin), float(xmax), float(ymax), resolution)
    counts = OccupancyCounts(spec)
    counts.add_rays(origins, ends)
    pixels = counts.image()
    info = _written(pixels, spec, target, tile)
    info.update(
        missions=cast,
        without_scans=[name for name in missions if name not in cast],
        scans=sum(found[n].scans for n in cast),
        rays=len(ends),
    )
    return info


def write_stored_grids(
    peer: Peer,
    time: int,
    missions: list[str],
    target: Path,
    box: BBox | None,
    resolution: float | None,
    frame: str = MISSION,
    tile: int | None = None,
) -> dict[str, object]:
    """Write the stored occupancy grids of `missions` as of `time`, composed over
    `box` (default: around their tiles) at their resolution in `frame`, as the
    nav2 YAML `target` and the PGM beside it, or as tiles of `tile` cells a
    side; what was written (as `grid_missions` says it). In the world frame,
    each mission's cells are moved by its place there (`plane.planar_placement`)
    and resampled into the world's axes (`occupancy.compose_tiles`).

    Raises:
        UsageError: a mission holds no grid tiles here, the grids' resolutions
            differ, `resolution` is not theirs (stored grids are not
            resampled to another), the grid would be too large
            (`grid.MAX_SIDE`), or in the world frame a mission has no place
            there or its place tilts the plane.
        MapImportError: no such mission.
    """
    places = {} if frame == MISSION else grid_places(peer, time, missions)
    tiles = []
    for name in missions:
        mission_row(peer, time, name)
        found = rows_of(peer, time, GRIDS, name)
        if not found:
            raise UsageError(
                f"no grid tiles of {name!r} here; `mapctl query-bbox --load` fetches them"
            )
        tiles.extend(found)
    stored = sorted({t.resolution for t in tiles})
    side = stored[0]
    if len(stored) > 1 or (resolution is not None and abs(resolution - side) > 1e-9 * side):
        raise UsageError(
            f"{', '.join(map(repr, missions))} store(s) grids of {', '.join(map(str, stored))} m "
            f"a cell{'' if resolution is None else f', not {resolution} m'}; stored grids are "
            "written at their own resolution: choose grids of one resolution, without "
            "--resolution"
        )
    if box is None:
        area = tiles_box(tiles, places)
        # whole cells: half a cell less keeps float rounding from adding a column
        # (grid_spec rounds the count up)
        xmax, ymax = area.xmax - side / 2, area.ymax - side / 2
    else:
        area, xmax, ymax = box, box.xmax, box.ymax
    spec = grid_spec(area.xmin, area.ymin, xmax, ymax, side)
    info = _written(nav2_pixels(compose_tiles(tiles, spec, places)), spec, target, tile)
    info.update(missions=missions, without_scans=[], scans=0, rays=0)
    return info


def grid_places(peer: Peer, time: int, missions: list[str]) -> dict[str, Placement]:
    """Each grid mission's place in the world frame as of `time`, as a motion of
    the plane.

    Raises:
        UsageError: a mission has no place there, or its place tilts the plane.
    """
    hint = (
        "give it one with a `frames` row (`mapctl set frames`, docs/guide/maps.md), or write "
        "it in its own frame (--frame mission)"
    )
    return {
        name: planar_placement(
            place_in_world(peer, time, name, hint).pose, f"the place of {name!r} in the world"
        )
        for name in missions
    }


def _written(
    pixels: npt.NDArray[np.uint8], spec: GridSpec, target: Path, tile: int | None
) -> dict[str, object]:
    """Write `pixels` as nav2's map at `target`, or with `tile`, as tiles of that
    many cells a side and their index (`map_tiles`); what a grid's JSON says of it."""
    if tile is None:
        files: dict[str, object] = {
            "path": str(target),
            "image": str(write_nav2(pixels, spec, target)),
            "tile": None,
            "tiles": [],
            "skipped": 0,
        }
    else:
        tiled = write_tiles(pixels, spec, target, tile)
        files = {
            "path": str(tiled.index),
            "image": None,
            "tile": tile,
            "tiles": [_tile_json(t) for t in tiled.tiles],
            "skipped": tiled.skipped,
        }
    return {
        **files,
        "width": spec.width,
        "height": spec.height,
        "resolution": spec.resolution,
        "origin": [spec.x0, spec.y0, 0.0],
        "cells": {
            "occupied": int(np.count_nonzero(pixels == OCCUPIED)),
            "free": int(np.count_nonzero(pixels == FREE)),
            "unknown": int(np.count_nonzero(pixels == UNKNOWN)),
        },
    }


def _tile_json(tile: MapTile) -> dict[str, object]:
    """What a grid's JSON says of one tile written."""
    return {
        "row": tile.row,
        "col": tile.col,
        "path": str(tile.yaml),
        "image": str(tile.image),
        "width": tile.spec.width,
        "height": tile.spec.height,
        "origin": [tile.spec.x0, tile.spec.y0, 0.0],
    }
