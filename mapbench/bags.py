"""Small synthetic ROS bags, written with `rosbags`: for the tests, the guide's
examples and `mapctl bench import --file`.

A bag holds a robot driving a helix: `nav_msgs/Odometry` on `/odom` (frame `odom`,
child `base_link`), the same poses as one `nav_msgs/Path` on `/path` (frame
`map`), `/tf_static` (map -> odom) and, every `cloud_every` poses, a ring of
points around the robot as `sensor_msgs/PointCloud2` on `/points` (frame `odom`)
and, if asked, a `nav_msgs/OccupancyGrid` on `/map`: twice, all unknown then
a room of 300 x 200 cells of 5 cm (`room_cells`), as a mapper republishes its map.
With `lidar`, the ring comes from a lidar on the robot, as a sensor gives it:
in frame `lidar` (mounted at `LIDAR_MOUNT` on `base_link`, in `/tf_static`),
with the robot's odom -> base_link on `/tf` at each pose; placed through TF,
it is the same ring in `odom`.

    python -m mapbench.bags run1.bag --poses 200          # ROS 1
    python -m mapbench.bags run2 --storage mcap          # ROS 2, a folder
    python -m mapbench.bags run3 --storage mcap --lidar  # clouds in a sensor's frame
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

import numpy as np

from mapapi.maps.alignment import pose_matrix
from mapapi.maps.bag_export import cloud_message, pose_message
from mapapi.maps.cloud import moved
from mapapi.maps.se3 import IDENTITY, Pose, compose, inverse

STORAGES = ("ros1", "sqlite3", "mcap")
_T0 = 10**9 * 1_700_000_000  # the first message's time, ns
GRID_RESOLUTION = 0.05
GRID_ORIGIN: Pose = (-7.5, -5.0, 0.0, 0.0, 0.0, 0.0, 1.0)
"""The corner of `room_cells` in the bags' grid: the room spans x -7.5..7.5, y -5..5."""
LIDAR_MOUNT: Pose = (0.3, 0.0, 0.2, 0.0, 0.0, math.sin(math.pi / 4), math.cos(math.pi / 4))
"""The lidar's pose on base_link: 30 cm ahead, 20 cm up, turned 90 degrees left."""


def helix_pose(i: int) -> Pose:
    """The robot's i-th pose: x, y, z, qx, qy, qz, qw (yaw along the helix)."""
    angle = 0.05 * i
    yaw = angle + math.pi / 2
    return (
        10 * math.cos(angle),
        10 * math.sin(angle),
        0.01 * i,
        0.0,
        0.0,
        math.sin(yaw / 2),
        math.cos(yaw / 2),
    )


class Messages:
    """Builds messages of one typestore (ROS 1 headers have a `seq`, ROS 2 not);
    each method returns one message, stamped `ns` nanoseconds."""

    def __init__(self, store: Any, ros1: bool) -> None:
        self.types, self.ros1 = store.types, ros1

    def header(self, ns: int, frame: str) -> Any:
        """A `std_msgs/Header`."""
        stamp = self.types["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
        if self.ros1:
            return self.types["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id=frame)
        return self.types["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)

    def pose(self, values: Pose) -> Any:
        """A `geometry_msgs/Pose` of a pose 7-tuple."""
        return pose_message(self.types, values)

    def odometry(self, ns: int, values: Pose) -> Any:
        """A `nav_msgs/Odometry` from odom to base_link."""
        t = self.types
        zero = t["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
        twist = t["geometry_msgs/msg/Twist"](linear=zero, angular=zero)
        return t["nav_msgs/msg/Odometry"](
            header=self.header(ns, "odom"),
            child_frame_id="base_link",
            pose=t["geometry_msgs/msg/PoseWithCovariance"](
                pose=self.pose(values), covariance=np.zeros(36)
            ),
            twist=t["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=np.zeros(36)),
        )

    def path(self, stamps: list[int], poses: list[Pose]) -> Any:
        """A `nav_msgs/Path` of every pose, in map."""
        stamped = self.types["geometry_msgs/msg/PoseStamped"]
        items = [
            stamped(header=self.header(ns, "map"), pose=self.pose(p))
            for ns, p in zip(stamps, poses, strict=True)
        ]
        return self.types["nav_msgs/msg/Path"](header=self.header(stamps[-1], "map"), poses=items)

    def cloud(self, ns: int, points: np.ndarray, frame: str = "odom") -> Any:
        """A `sensor_msgs/PointCloud2` of float32 x, y, z."""
        return cloud_message(self.types, self.header(ns, frame), points)

    def tf(self, ns: int, parent: str, child: str, pose: Pose = IDENTITY) -> Any:
        """A `tf2_msgs/TFMessage` of one transform: `child`'s pose in `parent`."""
        t = self.types
        x, y, z, qx, qy, qz, qw = pose
        transform = t["geometry_msgs/msg/Transform"](
            translation=t["geometry_msgs/msg/Vector3"](x=x, y=y, z=z),
            rotation=t["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=qw),
        )
        stamped = t["geometry_msgs/msg/TransformStamped"](
            header=self.header(ns, parent), child_frame_id=child, transform=transform
        )
        return t["tf2_msgs/msg/TFMessage"](transforms=[stamped])

    def grid(
        self, ns: int, cells: np.ndarray, origin: Pose, resolution: float = GRID_RESOLUTION
    ) -> Any:
        """A `nav_msgs/OccupancyGrid` in map of int8 `cells` (height x width, row 0
        the bottom), its corner at `origin`."""
        t = self.types
        height, width = cells.shape
        info = t["nav_msgs/msg/MapMetaData"](
            map_load_time=self.header(ns, "").stamp,
            resolution=resolution,
            width=width,
            height=height,
            origin=self.pose(origin),
        )
        data = np.ascontiguousarray(cells, dtype=np.int8).ravel()
        return t["nav_msgs/msg/OccupancyGrid"](header=self.header(ns, "map"), info=info, data=data)


def room_cells(width: int = 300, height: int = 200) -> np.ndarray:
    """A room as a grid's int8 cells (row 0 the bottom): free inside, walls of
    100 around it and along a partition, an unknown corner (-1), a patch of 50
    (neither free nor occupied) and cells of 20 and 70 (free and occupied)."""
    cells = np.zeros((height, width), dtype=np.int8)
    cells[[0, -1], :] = 100
    cells[:, [0, -1]] = 100
    cells[: height // 2, width // 3] = 100  # a partition from the bottom wall
    cells[-40:, -60:] = -1  # the top-right corner never seen
    cells[20:30, 20:30] = 50
    cells[40:45, 40:45] = 20
    cells[50:55, 50:55] = 70
    return cells


def ring(center: Pose, count: int) -> np.ndarray:
    """`count` points on a 2 m circle around `center`'s position, in its frame's axes."""
    angles = np.linspace(0.0, 2 * math.pi, count, endpoint=False)
    x, y, z = center[:3]
    return np.stack([x + 2 * np.cos(angles), y + 2 * np.sin(angles), np.full(count, z)], axis=1)


def write_bag(
    path: str | Path,
    storage: str = "ros1",
    *,
    poses: int = 100,
    cloud_every: int = 10,
    cloud_points: int = 64,
    grid: bool = False,
    lidar: bool = False,
) -> Path:
    """Write a helix bag (see the module docstring) at `path`: a `.bag` file for
    `ros1`, a folder for `sqlite3` and `mcap`. Returns `path`."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    path = Path(path)
    ros1 = storage == "ros1"
    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    if ros1:  # rosbags' Noetic store lacks tf2_msgs, which ROS 1 bags use for /tf
        tf = "geometry_msgs/TransformStamped[] transforms"
        store.register(get_types_from_msg(tf, "tf2_msgs/msg/TFMessage"))
    build = Messages(store, ros1)
    stamps = [_T0 + i * 10**8 for i in range(poses)]  # 10 Hz
    track = [helix_pose(i) for i in range(poses)]
    with _writer(path, storage) as writer:

        def connect(topic: str, msgtype: str) -> Any:
            return writer.add_connection(topic, msgtype, typestore=store)

        def put(connection: Any, ns: int, message: Any) -> None:
            raw = store.serialize_ros1 if ros1 else store.serialize_cdr
            writer.write(connection, ns, raw(message, connection.msgtype))

        tf = connect("/tf_static", "tf2_msgs/msg/TFMessage")
        odom = connect("/odom", "nav_msgs/msg/Odometry")
        cloud = connect("/points", "sensor_msgs/msg/PointCloud2") if cloud_every else None
        put(tf, stamps[0], build.tf(stamps[0], "map", "odom"))
        moving = connect("/tf", "tf2_msgs/msg/TFMessage") if lidar else None
        if lidar:
            put(tf, stamps[0], build.tf(stamps[0], "base_link", "lidar", LIDAR_MOUNT))
        for i, (ns, pose) in enumerate(zip(stamps, track, strict=True)):
            put(odom, ns, build.odometry(ns, pose))
            if moving is not None:
                put(moving, ns, build.tf(ns, "odom", "base_link", pose))
            if cloud is not None and i % cloud_every == 0:
                points = ring(pose, cloud_points)
                if lidar:  # as the lidar sees them: odom -> lidar is inverse(pose . mount)
                    sensor = pose_matrix(inverse(compose(pose, LIDAR_MOUNT)))
                    put(cloud, ns, build.cloud(ns, moved(points, sensor), "lidar"))
                else:
                    put(cloud, ns, build.cloud(ns, points))
        if poses:
            put(connect("/path", "nav_msgs/msg/Path"), stamps[-1], build.path(stamps, track))
        if grid:  # an unknown map first: the last message is the map
            room = room_cells()
            grid_topic = connect("/map", "nav_msgs/msg/OccupancyGrid")
            unknown = np.full(room.shape, -1, np.int8)
            first, last = (stamps[0], stamps[-1]) if stamps else (_T0, _T0 + 1)
            put(grid_topic, first, build.grid(first, unknown, GRID_ORIGIN))
            put(grid_topic, last, build.grid(last, room, GRID_ORIGIN))
    return path


def _writer(path: Path, storage: str) -> Any:
    if storage == "ros1":
        from rosbags.rosbag1 import Writer as Writer1

        return Writer1(path)
    from rosbags.rosbag2 import StoragePlugin, Writer

    plugin = {"sqlite3": StoragePlugin.SQLITE3, "mcap": StoragePlugin.MCAP}[storage]
    return Writer(path, version=9, storage_plugin=plugin)


def main() -> None:
    """Write one helix bag (`python -m mapbench.bags PATH [--storage ...]`)."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("path", type=Path)
    parser.add_argument("--storage", choices=STORAGES, default="ros1")
    parser.add_argument("--poses", type=int, default=100)
    parser.add_argument("--cloud-every", type=int, default=10, help="0: no clouds")
    parser.add_argument("--cloud-points", type=int, default=64)
    parser.add_argument("--grid", action="store_true", help="add an OccupancyGrid on /map")
    parser.add_argument(
        "--lidar", action="store_true", help="clouds in a lidar's frame, placed by /tf"
    )
    args = parser.parse_args()
    options = {name: getattr(args, name) for name in ("poses", "cloud_every", "cloud_points")}
    write_bag(args.path, args.storage, grid=args.grid, lidar=args.lidar, **options)
    print(f"wrote {args.path} ({args.storage}): {args.poses} poses")


if __name__ == "__main__":
    main()
