"""ROS 2 bags holding one occupancy grid, for the grid tests: its origin any
pose (turned, tilted), which `mapbench.bags` does not write."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mapapi.maps.se3 import Pose
from mapbench.bags import GRID_RESOLUTION, Messages

OCCUPANCY = "nav_msgs/msg/OccupancyGrid"


def write_grid_bag(
    folder: Path,
    cells: np.ndarray,
    origin: Pose,
    topic: str = "/map",
    resolution: float = GRID_RESOLUTION,
) -> Path:
    """Write a ROS 2 bag (MCAP) at the new `folder` of one `nav_msgs/OccupancyGrid`
    on `topic`: int8 `cells` (height x width, row 0 the bottom) from `origin`.
    Returns `folder`."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    message = Messages(store, ros1=False).grid(1, cells, origin, resolution)
    with Writer(folder, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connection = writer.add_connection(topic, OCCUPANCY, typestore=store)
        writer.write(connection, 1, store.serialize_cdr(message, OCCUPANCY))
    return folder
