"""ROS messages as map values: the poses, times, points and occupancy grids of
the messages a bag holds, and the point cloud message a bag export writes.

The messages are the objects `rosbags` deserialises (ROS 1 and ROS 2 alike: its
type names are `pkg/msg/Type` for both); they are read by attribute, so this
module needs numpy only, not rosbags. Pure: no file, no network.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

from mapapi.maps.cloud import Points
from mapapi.maps.se3 import Pose

ODOMETRY = "nav_msgs/msg/Odometry"
PATH = "nav_msgs/msg/Path"
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
POINT_CLOUD = "sensor_msgs/msg/PointCloud2"
OCCUPANCY_GRID = "nav_msgs/msg/OccupancyGrid"
TF_TYPES = ("tf2_msgs/msg/TFMessage", "tf/msg/tfMessage")  # ROS 2 and newer ROS 1; old ROS 1
POSE_TYPES = (ODOMETRY, PATH, POSE_STAMPED)

# sensor_msgs/PointField datatypes a coordinate may have: FLOAT32 and FLOAT64
_FLOAT_FIELDS = {7: "f4", 8: "f8"}
FLOAT32_FIELD = 7

Stamped = tuple[float, Pose, str]  # (time in seconds, pose, the frame it is in)


def stamp_seconds(stamp: Any) -> float:
    """A `builtin_interfaces/Time` (ROS 1 `time`) in seconds."""
    return float(stamp.sec) + float(stamp.nanosec) * 1e-9


def pose_of(pose: Any) -> Pose:
    """A `geometry_msgs/Pose` as a pose 7-tuple, its quaternion made a unit.

    Raises:
        ValueError: a value is not finite, or the quaternion is zero.
    """
    return _unit_pose(pose.position, pose.orientation)


def transform_of(transform: Any) -> Pose:
    """A `geometry_msgs/Transform` as a pose 7-tuple (as `pose_of`).

    Raises:
        ValueError: a value is not finite, or the quaternion is zero.
    """
    return _unit_pose(transform.translation, transform.rotation)


def _unit_pose(p: Any, q: Any) -> Pose:
    values = (p.x, p.y, p.z, q.x, q.y, q.z, q.w)
    if not all(map(math.isfinite, values)):
        raise ValueError(f"the pose {values} has a value that is not a finite number")
    norm = math.sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w)
    if norm < 1e-9:
        raise ValueError("the pose's quaternion is zero")
    return (p.x, p.y, p.z, q.x / norm, q.y / norm, q.z / norm, q.w / norm)


def frame_name(frame_id: str) -> str:
    """A TF frame id without the leading slash ROS 1 allowed (`/odom` is `odom`)."""
    return frame_id.lstrip("/")


def stamped_poses(msgtype: str, message: Any, received: float) -> list[Stamped]:
    """The poses a pose message holds, each with its time (its header's stamp, or
    `received`, when the bag recorded it, if the stamp is zero) and frame: one for
    an odometry or a stamped pose, the whole path for a path."""
    if msgtype == PATH:
        return [_stamped(p.header, p.pose, received) for p in message.poses]
    pose = message.pose.pose if msgtype == ODOMETRY else message.pose
    return [_stamped(message.header, pose, received)]


def _stamped(header: Any, pose: Any, received: float) -> Stamped:
    return (stamp_seconds(header.stamp) or received, pose_of(pose), frame_name(header.frame_id))


def cloud_points(message: Any) -> tuple[Points, int]:
    """The x, y, z of a `sensor_msgs/PointCloud2` as float32, and how many points
    were left out because a coordinate is not finite (a sensor's no-returns).

    Raises:
        ValueError: no float x, y or z field, or fewer bytes than the sizes say.
    """
    fields = {f.name: f for f in message.fields}
    order = ">" if message.is_bigendian else "<"
    formats = []
    for axis in "xyz":
        found = fields.get(axis)
        if found is None:
            raise ValueError(f"PointCloud2 has no field {axis!r} (fields: {', '.join(fields)})")
        if found.datatype not in _FLOAT_FIELDS:
            raise ValueError(
                f"PointCloud2 field {axis!r} is of PointField type {found.datatype}, "
                "not FLOAT32 (7) or FLOAT64 (8)"
            )
        formats.append(order + _FLOAT_FIELDS[found.datatype])
    offsets = [fields[axis].offset for axis in "xyz"]
    layout = np.dtype(
        {
            "names": list("xyz"),
            "formats": formats,
            "offsets": offsets,
            "itemsize": message.point_step,
        }
    )
    width, height, row = message.width, message.height, message.row_step
    data = np.ascontiguousarray(message.data, dtype=np.uint8)
    if row < width * message.point_step or len(data) < row * height:
        raise ValueError(
            f"PointCloud2 of {height} x {width} points of {message.point_step} bytes "
            f"(rows of {row}) holds {len(data)} bytes"
        )
    rows = data[: row * height].reshape(height, row)[:, : width * message.point_step]
    records = np.frombuffer(np.ascontiguousarray(rows), dtype=layout, count=width * height)
    points = np.stack([records["x"], records["y"], records["z"]], axis=1).astype(np.float32)
    finite = np.isfinite(points).all(axis=1)
    return points[finite], int(len(points) - int(finite.sum()))


Link = tuple[str, str, float, Pose]
"""(parent frame, child frame, stamp in seconds, the child's pose in the parent)."""


def tf_links(message: Any) -> list[Link]:
    """The transforms of a TF message, each from its header's frame to its child.

    Raises:
        ValueError: a transform that is not finite, or of a zero quaternion.
    """
    return [
        (
            frame_name(t.header.frame_id),
            frame_name(t.child_frame_id),
            stamp_seconds(t.header.stamp),
            transform_of(t.transform),
        )
        for t in message.transforms
    ]


GridCells = tuple[float, float, float, float, float, npt.NDArray[np.int8]]
"""(resolution, origin x, y, z, yaw, cells (height, width), row 0 the bottom)."""


def grid_cells(message: Any) -> GridCells:
    """A `nav_msgs/OccupancyGrid`'s resolution, origin (with its yaw) and int8 cells.

    A grid whose origin is turned about z is read with its yaw: its tiles keep
    it (`mapapi.maps.occupancy`), and writing it for nav2 (whose YAML yaw
    map_server ignores) resamples it along the frame's axes. A grid tilted out
    of the plane (roll or pitch) is not a 2D map of that frame.

    Raises:
        ValueError: a tilted origin, a resolution that is not positive, or fewer
            or more cells than width x height.
    """
    info = message.info
    x, y, z, qx, qy, qz, qw = pose_of(info.origin)
    yaw = math.atan2(2 * (qw * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz))
    if abs(qx) > 1e-9 or abs(qy) > 1e-9:
        raise ValueError(
            f"the grid's origin is tilted (qx {qx:.6f}, qy {qy:.6f}); only grids turned "
            "about z alone are imported"
        )
    if not info.resolution > 0:
        raise ValueError(f"the grid's resolution is {info.resolution}, not positive")
    width, height = int(info.width), int(info.height)
    data = np.asarray(message.data).astype(np.int8, copy=False)
    if len(data) != width * height:
        raise ValueError(f"OccupancyGrid of {width} x {height} cells holds {len(data)}")
    # ROS states the resolution as a float32: 0.05 arrives as 0.0500000007; its
    # shortest float32 decimal gives back the 0.05 the map was made with
    resolution = float(str(np.float32(info.resolution)))
    return resolution, x, y, z, yaw, data.reshape(height, width)
