"""A mission as a ROS 2 bag (MCAP storage), written through `rosbags`.

The bag (a folder, as every ROS 2 bag) holds, for mission M (its name made a
valid ROS name: `t1-odom` gives `/t1_odom/...`):

- `/M/pose`: a `geometry_msgs/PoseStamped` per vertex, in index order, stamped
  with the vertex's timestamp (its index in seconds when the mission has none,
  as for TUM: `mapapi.maps.trajectory`);
- `/M/path`: one `nav_msgs/Path` of every pose, stamped with the last pose's time;
- `/M/cloud`: a `sensor_msgs/PointCloud2` (float32 x, y, z) per stored point
  block: a laser scan's block is stamped with its vertex's time, a cloud's
  blocks with time 0;
- `/M/map`: one `nav_msgs/OccupancyGrid` of its stored grid (a bag's grid
  mission: `mapapi.maps.occupancy`), its tiles put back together cell for
  cell, at their resolution and origin, stamped with the grid's stamp.

Every message's frame is the mission's frame (`Mission.frame`) or, with
`frame="world"`, `world`, the poses and points moved by the mission's place
there (`mapctl align`; a grid is written in its mission's frame only: turning
it would resample its cells). Each message is also recorded at its stamp. `rosbags`
is imported when a bag is written.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from mapapi.core.errors import UsageError
from mapapi.maps.bag_messages import (
    FLOAT32_FIELD,
    OCCUPANCY_GRID,
    PATH,
    POINT_CLOUD,
    POSE_STAMPED,
)
from mapapi.maps.cloud import Points, block_points, moved
from mapapi.maps.frames import MISSION, WORLD, frame_at, graph_in
from mapapi.maps.grid import GridSpec
from mapapi.maps.occupancy import OccupancyGrid, compose_tiles
from mapapi.maps.schema import CLOUDS, GRIDS, GridTile
from mapapi.maps.se3 import Pose
from mapapi.maps.stored import rows_of
from mapapi.maps.trajectory import trajectory_of
from mapapi.service.peer import Peer

BAG_FORMAT = "bag"
_NOT_IN_NAME = re.compile(r"[^A-Za-z0-9_]")


def topic_prefix(mission: str) -> str:
    """`/` and the mission's name as a ROS name token: characters other than
    letters, digits and `_` become `_`, and a leading digit gets a `_` before it
    (ROS 2 names allow neither)."""
    token = _NOT_IN_NAME.sub("_", mission) or "_"
    return f"/_{token}" if token[0].isdigit() else f"/{token}"


@dataclass
class BagContent:
    """What a mission's bag holds.

    Attributes:
        frame: every message's `frame_id`.
        stamps, poses: the trajectory, in index order (empty for a cloud).
        timed: the stamps are the vertices' own timestamps (else their indices).
        scans: (stamp in seconds, points) per stored point block.
        grid: its stored occupancy grid, if it has one.
    """

    mission: str
    frame: str
    stamps: list[float] = field(default_factory=list)
    poses: list[Pose] = field(default_factory=list)
    timed: bool = False
    scans: list[tuple[float, Points]] = field(default_factory=list)
    grid: OccupancyGrid | None = None


def bag_content(peer: Peer, time: int, mission: str, frame: str = MISSION) -> BagContent:
    """Read `mission` as of `time` for a bag, its poses and points in `frame`.

    Raises:
        UsageError: in the world frame, the mission was never aligned or has a grid.
        MapImportError: no such mission.
    """
    graph = graph_in(peer, time, mission, frame)
    tiles = rows_of(peer, time, GRIDS, mission)
    if tiles and frame != MISSION:
        raise UsageError(
            f"mission {mission!r} holds an occupancy grid, which a bag holds in its "
            "mission's frame only (--frame mission)"
        )
    trajectory = trajectory_of(graph)
    content = BagContent(mission, graph.frame or f"{mission}/map")
    content.stamps, content.poses, content.timed = (
        trajectory.stamps,
        trajectory.poses,
        trajectory.timed,
    )
    move = None
    if frame != MISSION:
        from mapapi.maps.alignment import pose_matrix

        found = frame_at(peer, time, mission)
        assert found is not None  # graph_in raised otherwise
        move, content.frame = pose_matrix(found.pose), WORLD
    when = dict(zip(sorted(graph.vertices), trajectory.stamps, strict=True))
    blocks = rows_of(peer, time, CLOUDS, mission)
    blocks.sort(key=lambda b: b.vertex if b.HasField("vertex") else -1)  # scans in pose order
    for block in blocks:
        points = block_points(block)
        if move is not None:
            points = moved(points, move)
        stamp = when.get(block.vertex, 0.0) if block.HasField("vertex") else 0.0
        content.scans.append((stamp, points))
    if tiles:
        content.grid = stored_grid(graph.name, graph.robot, content.frame, tiles)
    return content


def stored_grid(name: str, robot: str, frame: str, tiles: list[GridTile]) -> OccupancyGrid:
    """The grid a mission's tiles were cut from (`occupancy.grid_tiles`): cell for
    cell, its corner the lowest tile's, its stamp theirs.

    Raises:
        UsageError: tiles of more than one resolution (no import makes them).
    """
    sides = {t.resolution for t in tiles}
    if len(sides) > 1:
        found = ", ".join(map(str, sorted(sides)))
        raise UsageError(f"mission {name!r} holds grid tiles of {found} m a cell: not one grid")
    side = sides.pop()
    x0, y0 = min(t.x for t in tiles), min(t.y for t in tiles)
    # tile corners lie on the grid's lattice: a whole number of cells from x0, y0
    width = max(round((t.x - x0) / side) + t.width for t in tiles)
    height = max(round((t.y - y0) / side) + t.height for t in tiles)
    cells = compose_tiles(tiles, GridSpec(x0, y0, side, width, height))
    z = tiles[0].bbox.zmin
    return OccupancyGrid(name, robot, frame, side, x0, y0, z, cells, max(t.stamp for t in tiles))


def write_bag(content: BagContent, target: Path) -> dict[str, Any]:
    """Write `content` as a ROS 2 MCAP bag in the new folder `target` (see the
    module docstring); what was written.

    Raises:
        UsageError: `target` exists, the mission holds nothing, or rosbags is missing.
    """
    if target.exists():
        raise UsageError(f"{target} exists; a bag is a new folder: remove it or choose another")
    if not content.poses and not content.scans and content.grid is None:
        raise UsageError(
            f"mission {content.mission!r} has neither poses, points nor a grid to write"
        )
    try:
        from rosbags.rosbag2 import StoragePlugin, Writer
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise UsageError(
            "ROS bags need rosbags; install it with `pip install 'mapapi[rosbag]'`"
        ) from None
    store = get_typestore(Stores.ROS2_HUMBLE)
    build = _Builder(store.types, content.frame)
    prefix = topic_prefix(content.mission)
    topics = []
    with Writer(target, version=9, storage_plugin=StoragePlugin.MCAP) as writer:

        def put(topic: str, msgtype: str, items: list[tuple[float, Any]]) -> None:
            connection = writer.add_connection(topic, msgtype, typestore=store)
            topics.append(topic)
            for stamp, message in items:
                writer.write(connection, _ns(stamp), store.serialize_cdr(message, msgtype))

        if content.poses:
            stamped = [
                build.pose_stamped(s, p) for s, p in zip(content.stamps, content.poses, strict=True)
            ]
            put(f"{prefix}/pose", POSE_STAMPED, list(zip(content.stamps, stamped, strict=True)))
            path = build.types[PATH](header=build.header(content.stamps[-1]), poses=stamped)
            put(f"{prefix}/path", PATH, [(content.stamps[-1], path)])
        if content.scans:
            clouds = [(s, build.cloud(s, points)) for s, points in content.scans]
            put(f"{prefix}/cloud", POINT_CLOUD, clouds)
        if content.grid is not None:
            grid = content.grid
            put(f"{prefix}/map", OCCUPANCY_GRID, [(grid.stamp, build.grid(grid))])
    return {
        "poses": len(content.poses),
        "points": sum(len(p) for _, p in content.scans),
        "grid_cells": 0 if content.grid is None else int(content.grid.cells.size),
        "time": "timestamp" if content.timed else "index",
        "topics": topics,
    }


def export_bag(
    peer: Peer, time: int, mission: str, target: Path, frame: str = MISSION
) -> dict[str, Any]:
    """`write_bag` of `bag_content`: the export job of the `bag` format."""
    return write_bag(bag_content(peer, time, mission, frame), target)


def _ns(stamp: float) -> int:
    return round(stamp * 1e9)


class _Builder:
    """Builds the ROS 2 messages of one bag, all in `frame`."""

    def __init__(self, types: Any, frame: str) -> None:
        self.types, self.frame = types, frame

    def header(self, stamp: float) -> Any:
        ns = _ns(stamp)
        time = self.types["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
        return self.types["std_msgs/msg/Header"](stamp=time, frame_id=self.frame)

    def pose_stamped(self, stamp: float, pose: Pose) -> Any:
        return self.types[POSE_STAMPED](
            header=self.header(stamp), pose=pose_message(self.types, pose)
        )

    def cloud(self, stamp: float, points: Points) -> Any:
        return cloud_message(self.types, self.header(stamp), points)

    def grid(self, grid: OccupancyGrid) -> Any:
        """A `nav_msgs/OccupancyGrid` of `grid`: its cells as stored, row 0 the bottom."""
        header = self.header(grid.stamp)
        height, width = grid.cells.shape
        info = self.types["nav_msgs/msg/MapMetaData"](
            map_load_time=header.stamp,
            resolution=grid.resolution,
            width=width,
            height=height,
            origin=pose_message(self.types, (grid.x0, grid.y0, grid.z, 0.0, 0.0, 0.0, 1.0)),
        )
        data = np.ascontiguousarray(grid.cells, dtype=np.int8).reshape(-1)
        return self.types[OCCUPANCY_GRID](header=header, info=info, data=data)


def pose_message(types: Any, pose: Pose) -> Any:
    """A `geometry_msgs/Pose` of a pose 7-tuple, of the typestore whose `types` are given."""
    x, y, z, qx, qy, qz, qw = pose
    return types["geometry_msgs/msg/Pose"](
        position=types["geometry_msgs/msg/Point"](x=x, y=y, z=z),
        orientation=types["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=qw),
    )


def cloud_message(types: Any, header: Any, points: Points) -> Any:
    """A `sensor_msgs/PointCloud2` of `points` as float32 x, y, z (one row, dense)."""
    fields = [
        types["sensor_msgs/msg/PointField"](name=a, offset=4 * k, datatype=FLOAT32_FIELD, count=1)
        for k, a in enumerate("xyz")
    ]
    data = np.ascontiguousarray(points, dtype="<f4").view(np.uint8).reshape(-1)
    return types[POINT_CLOUD](
        header=header,
        height=1,
        width=len(points),
        fields=fields,
        is_bigendian=False,
        point_step=12,
        row_step=12 * len(points),
        data=data,
        is_dense=True,
    )
