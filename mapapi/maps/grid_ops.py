"""`mapctl grid`: an occupancy grid of laser missions for nav2's `map_server`
(issue 17 §4), as an operation of the peer (in its daemon when one runs).

The casting (`mapapi.maps.grid_job.grid_missions`, numpy over every ray of
every scan: seconds for a large log) runs off the event loop, in a process of
its own while the peer serves a swarm (`jobs.run_job`), reading the missions
as of one time (`stored.read_time`), as `export` and `plot` do.

A command of its own: a grid covers a box of the merged map, from any number
of missions, chosen as `plot` chooses them. `export MISSION -o FILE.yaml`
(format `grid`) delegates here (`export_grid`): the grid of that one mission.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from mapapi.core.errors import UsageError
from mapapi.lookup.spatial import BBox
from mapapi.service.ops import Operation

if TYPE_CHECKING:
    from mapapi.service.peer import Peer

Json = Any

DEFAULT_RESOLUTION = 0.05
"""Metres per cell: nav2's usual 5 cm."""


def grid_target(path: str) -> Path:
    """The YAML file to write a grid to, absolute (the PGM goes beside it).

    Raises:
        UsageError: `path` does not end in .yaml or .yml.
    """
    target = Path(path).expanduser().absolute()
    if target.suffix.lower() not in (".yaml", ".yml"):
        raise UsageError(
            f"a grid is written as nav2's YAML and a PGM beside it: name the .yaml file, "
            f"not {target.name!r}"
        )
    return target


EXPORTED = ("image", "width", "height", "resolution", "origin", "cells", "scans")
"""What `export_grid` tells of the grid, beside what every export tells."""


class GridOperations:
    """The `grid_map` operation over one peer, and `export_grid`, which
    `MapOperations.export_map` delegates a nav2 map (`.yaml`) to."""

    def __init__(self, peer: Peer) -> None:
        self.peer = peer

    def operations(self) -> Mapping[str, Operation]:
        """See `mapapi.service.ops.OperationSet`."""
        return {"grid_map": self.grid_map}

    async def grid_map(
        self,
        path: str,
        missions: list[str] | None = None,
        bbox: list[float] | None = None,
        resolution: float | None = None,
        frame: str = "mission",
        tile: int | None = None,
    ) -> Json:
        """Cast the laser scans of the missions named or matching a pattern
        (default: every mission held here with scans, else every grid mission)
        into an occupancy grid over `bbox`'s x and y (default: around every
        ray), `resolution` metres a cell (default `DEFAULT_RESOLUTION`), in
        `frame` ("world" once placed there); write it as nav2's YAML `path` and a
        PGM beside it; with `tile`, as nav2 maps of at most `tile` cells a
        side and their index (`mapapi.maps.map_tiles`). Grid missions (a bag's
        occupancy grid) are written as stored, composed over `bbox`, at their
        own resolution; in the world frame, resampled into its axes.

        Raises:
            UsageError: a name matches no mission here, no mission has laser
                scans or a grid, laser and grid missions are mixed, the grid
                would exceed `grid.MAX_SIDE` cells a side, `tile` is below 1,
                in the world frame a mission was never placed there (or a grid
                mission's place tilts the plane), or a stored grid is asked
                for at another resolution.
        """
        from mapapi.maps.frames import MISSION, frame_reads
        from mapapi.maps.grid_job import grid_missions, write_stored_grids
        from mapapi.maps.jobs import run_job
        from mapapi.maps.schema import CLOUDS, FRAMES, GRIDS, MISSIONS
        from mapapi.maps.stored import read_time

        frame_reads(frame)  # refuses an unknown frame
        target = grid_target(path)
        if tile is not None and tile < 1:
            raise UsageError(f"a tile is at least one cell a side, not {tile}")
        box = None if bbox is None else BBox.from_tuple(bbox)
        chosen, gridded = await self._chosen(missions)
        started = time.perf_counter()
        if gridded:
            reads = (MISSIONS, GRIDS) if frame == MISSION else (MISSIONS, GRIDS, FRAMES)
            async with read_time(self.peer, chosen, reads) as at:
                info = await run_job(
                    self.peer, write_stored_grids, at, chosen, target, box, resolution, frame, tile
                )
        else:
            async with read_time(self.peer, chosen, (*frame_reads(frame), CLOUDS)) as at:
                info = await run_job(
                    self.peer,
                    grid_missions,
                    at,
                    chosen,
                    target,
                    box,
                    resolution or DEFAULT_RESOLUTION,
                    frame,
                    tile,
                )
        return {
            **info,
            "frame": frame,
            "bbox": None if box is None else list(box.as_tuple()),
            "seconds": round(time.perf_counter() - started, 3),
        }

    async def export_grid(self, mission: str, path: str, frame: str = "mission") -> Json:
        """Write the grid of one mission (its stored grid, or its scans cast at
        `DEFAULT_RESOLUTION`) in `frame` as nav2's YAML `path` and a PGM beside
        it: `grid_map` of that mission, said as `export` says what it wrote.

        Raises:
            UsageError: as `grid_map`; the mission has no laser scan nor grid.
        """
        info = await self.grid_map(path, [mission], frame=frame)
        told = {key: info[key] for key in EXPORTED}
        return {"mission": mission, "path": info["path"], "format": "grid", "frame": frame, **told}

    async def _chosen(self, missions: list[str] | None) -> tuple[list[str], bool]:
        """The missions to grid, and whether they are grid missions (whose stored
        cells are written) rather than laser missions (whose scans are cast).

        Raises:
            UsageError: a name matches no mission here, none has scans or a
                grid, or the names mix grid missions with others.
        """
        from mapapi.maps.schema import GRIDS
        from mapapi.maps.stored import choose_missions, list_missions

        held = await list_missions(self.peer)
        if missions:
            infos = choose_missions(held, missions, None)
            gridded = [i.name for i in infos if GRIDS in i.chunks]
            if gridded and len(gridded) < len(infos):
                others = [i.name for i in infos if GRIDS not in i.chunks]
                raise UsageError(
                    f"{', '.join(gridded)} hold(s) an occupancy grid and {', '.join(others)} "
                    "not: a grid is written from stored grids or cast from laser scans, "
                    "not both; choose one kind with -m"
                )
            return [i.name for i in infos], bool(gridded)
        lasers = [i.name for i in held if i.vertices and i.points]  # laser missions
        if lasers:
            return lasers, False
        grids = [i.name for i in held if GRIDS in i.chunks]
        if not grids:
            raise UsageError(
                "no mission with laser scans or an occupancy grid here; import a CARMEN log "
                "(.clf) or a ROS bag with a nav_msgs/OccupancyGrid first"
            )
        return grids, True
