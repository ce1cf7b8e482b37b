"""ROS bags (ROS 1 `.bag`, ROS 2 folders in SQLite3 or MCAP) as missions, read
through `rosbags` (pure Python: no ROS installation).

What becomes what (`read_bag`):

- each topic of `nav_msgs/Odometry`, `geometry_msgs/PoseStamped` or `nav_msgs/Path`
  is one trajectory mission, named after the bag and the topic (`run1-robot1-odom`
  for `/robot1/odom` in `run1.bag`): a vertex per pose, timed by its header's stamp
  (the bag's receive time when the stamp is zero), and an odometry edge between
  consecutive poses (their relative pose; a bag states no relative uncertainty, so
  every edge gets `INFORMATION`). A path topic republishes the whole path as it
  grows: its last message is the trajectory;
- each `sensor_msgs/PointCloud2` topic is one point cloud mission of every point of
  its messages; points with a coordinate that is not finite are left out. A
  message in another frame than the trajectory's (the frame of the first
  odometry topic read, else of the first pose topic) is moved there through TF
  at its stamp (`mapapi.maps.bag_clouds`), so clouds and poses line up; where
  TF joins no path, the points stay in their header's frame and the mission
  says so in its `warnings`;
- `/tf` and `/tf_static` (any topic ending so, for a robot's namespace) make
  the TF tree (`mapapi.maps.tf_tree`; a `tf_static` transform holds at every
  time), which places the clouds and names frames: a mission's frame is
  `<mission>/<frame_id>` of its messages' header, or, when that is empty, the
  TF parent of an odometry's `child_frame_id`. The tree itself is not stored;
- each `nav_msgs/OccupancyGrid` topic is one grid mission (`mapapi.maps.occupancy`)
  of its **last** message (a map is republished whole as it grows), in its
  header's frame, its origin's yaw kept with its tiles. A grid tilted out of
  the plane (an origin with roll or pitch) is refused, naming the topic.
  Other types are skipped.

Messages are read one at a time, in one pass (a bag never sits in memory; a
cloud's scans wait, as read, for the end of the bag, when TF is complete);
errors name the topic and the message's index on it. `rosbags` is imported when a bag is read,
so a command that never reads one does not load it.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mapapi.core.errors import UsageError
from mapapi.maps import bag_messages as msgs
from mapapi.maps.bag_clouds import BagCloud
from mapapi.maps.cloud import PointCloud
from mapapi.maps.errors import MapImportError
from mapapi.maps.graph import EdgeKind, GraphEdge, MissionGraph
from mapapi.maps.occupancy import OccupancyGrid
from mapapi.maps.se3 import Pose, compose, inverse, isotropic_information
from mapapi.maps.tf_tree import TfTree

log = logging.getLogger(__name__)

Progress = Callable[[int, int], None]  # (messages read, messages in all)
MapSource = MissionGraph | PointCloud | OccupancyGrid

FORMAT = "rosbag"
INFORMATION = isotropic_information(400.0, 1641.5)
"""Every odometry edge's information: 5 cm and 1 degree standard deviation on
each axis (2 kappa = 1 / 0.01745^2); a bag's odometry states no relative noise."""
_PROGRESS_EVERY = 1_000


def is_bag(path: Path) -> bool:
    """A ROS 1 bag (`.bag`) or a ROS 2 bag's folder (which holds `metadata.yaml`)."""
    if path.is_dir():
        return (path / "metadata.yaml").is_file()
    return path.suffix.lower() == ".bag"


def bag_name(path: Path) -> str:
    """A bag's name: the file's stem, or the folder's name."""
    return path.name if path.is_dir() else path.stem


def mission_name(prefix: str, topic: str) -> str:
    """The mission of `topic`: `prefix` then the topic's parts joined by `-`."""
    return prefix + "-".join(part for part in topic.split("/") if part)


@dataclass
class _Trajectory:
    """One pose topic's mission as it is read."""

    graph: MissionGraph
    frame: str = ""  # the header's frame id of its first pose
    child: str = ""  # an odometry's child_frame_id
    odometry: bool = False  # a nav_msgs/Odometry topic: its frame is where clouds go
    last: Pose | None = None

    def add(self, stamp: float, pose: Pose, frame: str) -> None:
        graph = self.graph
        index = len(graph.vertices)
        graph.vertices[index] = pose
        graph.timestamps[index] = stamp
        self.frame = self.frame or frame
        if self.last is not None:
            ends = (graph.name, index - 1), (graph.name, index)
            relative = compose(inverse(self.last), pose)
            graph.edges.append(GraphEdge(*ends, relative, INFORMATION, EdgeKind.ODOMETRY))
        self.last = pose

    def restart(self) -> None:
        """Forget what was read: a path message holds the whole path anew."""
        self.graph.vertices.clear()
        self.graph.timestamps.clear()
        self.graph.edges.clear()
        self.last = None


@dataclass
class _Bag:
    """What is read of a bag: the missions per topic, and the TF tree."""

    prefix: str
    robot: str
    trajectories: dict[str, _Trajectory] = field(default_factory=dict)
    clouds: dict[str, BagCloud] = field(default_factory=dict)
    tf: TfTree = field(default_factory=TfTree)
    grids: dict[str, OccupancyGrid] = field(default_factory=dict)

    def read(self, topic: str, msgtype: str, message: Any, received: float) -> None:
        if msgtype in msgs.TF_TYPES:
            static = topic.endswith("tf_static")
            for parent, child, stamp, pose in msgs.tf_links(message):
                self.tf.add(parent, child, stamp or received, pose, static=static)
        elif msgtype == msgs.OCCUPANCY_GRID:
            self.read_grid(topic, message, received)
        elif msgtype == msgs.POINT_CLOUD:
            name = mission_name(self.prefix, topic)
            self.clouds.setdefault(topic, BagCloud(topic, name)).add(message, received)
        else:
            track = self.trajectories.get(topic)
            if track is None:
                graph = MissionGraph(mission_name(self.prefix, topic), self.robot)
                track = self.trajectories[topic] = _Trajectory(graph)
            if msgtype == msgs.PATH:
                track.restart()
            elif msgtype == msgs.ODOMETRY:
                track.child = track.child or msgs.frame_name(message.child_frame_id)
                track.odometry = True
            for stamp, pose, frame in msgs.stamped_poses(msgtype, message, received):
                track.add(stamp, pose, frame)

    def read_grid(self, topic: str, message: Any, received: float) -> None:
        """Keep a grid message as its topic's grid: each replaces the last."""
        resolution, x, y, z, yaw, cells = msgs.grid_cells(message)
        name = mission_name(self.prefix, topic)
        frame = f"{name}/{msgs.frame_name(message.header.frame_id) or 'map'}"
        stamp = msgs.stamp_seconds(message.header.stamp) or received
        grid = OccupancyGrid(name, self.robot, frame, resolution, x, y, z, cells, stamp, yaw)
        self.grids[topic] = grid

    def missions(self, voxel: float, tf_frame: str | None = None) -> list[MapSource]:
        """The missions read, trajectories first, each in its frame; the clouds
        placed in `tf_frame`, by default the first odometry's frame (else the
        first trajectory's).

        Raises:
            UsageError: `tf_frame` is in no transform and is no trajectory's frame.
        """
        found: list[MapSource] = []
        frames = {}  # topic -> its trajectory's frame, without the mission's name
        for topic, track in self.trajectories.items():
            if not track.graph.vertices:
                log.warning("topic %s holds no pose: no mission", topic)
                continue
            frame = frames[topic] = track.frame or self.tf.parent(track.child) or "odom"
            track.graph.frame = f"{track.graph.name}/{frame}"
            found.append(track.graph)
        odometry = [t for t in frames if self.trajectories[t].odometry]
        target = frames[(odometry or list(frames))[0]] if frames else None
        if tf_frame is not None:
            known = self.tf.frames() | set(frames.values())
            if tf_frame not in known:
                named = ", ".join(sorted(known)) or "none"
                raise UsageError(f"--tf-frame {tf_frame}: no transform names it (frames: {named})")
            target = tf_frame
        for cloud in self.clouds.values():
            if (placed := self.cloud(cloud, target, voxel)) is not None:
                found.append(placed)
        for topic, grid in self.grids.items():
            if not grid.cells.size:
                log.warning("topic %s holds an empty grid: no mission", topic)
                continue
            found.append(grid)
        return found

    def cloud(self, cloud: BagCloud, target: str | None, voxel: float) -> PointCloud | None:
        """A cloud topic's mission, placed in frame `target` (None: no mission,
        since no point is left)."""
        placed = cloud.placed(self.tf, target)
        for warning in placed.warnings:
            log.warning("%s", warning)
        points = placed.points
        if voxel:
            from mapapi.maps.cloud_file import downsample  # open3d, only when asked

            points = downsample(points, voxel)
        if not len(points):
            log.warning("topic %s holds no finite point: no mission", cloud.topic)
            return None
        frame = f"{cloud.name}/{placed.frame or 'map'}"
        found = PointCloud(cloud.name, self.robot, frame, points, cloud.dropped)
        found.warnings.extend(placed.warnings)
        return found


def read_bag(
    path: str | Path,
    topics: Sequence[str] = (),
    mission: str | None = None,
    robot: str = "",
    *,
    voxel: float = 0.0,
    tf_frame: str | None = None,
    progress: Progress | None = None,
) -> list[MapSource]:
    """Read a ROS bag's pose, point cloud and occupancy grid topics as missions
    (see the module docstring).

    Args:
        topics: the topics to read (default: every supported one).
        mission: the prefix of every mission's name (default: the bag's name and `-`).
        robot: the robot of every mission.
        voxel: keep one point per voxel of this side in metres (open3d); 0 keeps all.
        tf_frame: the frame the clouds are placed in (default: the first odometry
            topic's frame, else the first pose topic's).
        progress: called with (messages read, messages in all).

    Raises:
        MapImportError: not a bag rosbags reads, a message that does not decode or
            is not a valid map value (naming the topic and the message's index on
            it: a tilted grid origin among them), or no supported topic with data.
        UsageError: rosbags is missing, or `topics` names a topic the bag lacks or
            one of a type not imported, or `tf_frame` is a frame no transform names.
    """
    path = Path(path)
    bag = _Bag(f"{bag_name(path)}-" if mission is None else mission, robot)
    with _open(path) as reader:
        chosen = _choose(reader.connections, topics, str(path))
        total = sum(c.msgcount for c in chosen)
        counts: dict[str, int] = {}
        read = 0
        for connection, received, raw in reader.messages(connections=chosen) if chosen else ():
            topic = connection.topic
            index = counts[topic] = counts.get(topic, -1) + 1
            try:
                message = reader.deserialize(raw, connection.msgtype)
                bag.read(topic, connection.msgtype, message, received * 1e-9)
            except Exception as exc:  # rosbags' and numpy's errors alike: name the message
                raise MapImportError(
                    f"topic {topic}, message {index} ({connection.msgtype}): {exc}",
                    source=str(path),
                ) from exc
            read += 1
            if progress is not None and read % _PROGRESS_EVERY == 0:
                progress(read, total)
    if progress is not None:
        progress(read, total)
    found = bag.missions(voxel, tf_frame)
    if not found:
        raise MapImportError(
            "no pose, point cloud or occupancy grid topic with data: nothing to import",
            source=str(path),
        )
    return found


@contextmanager
def _open(path: Path) -> Iterator[Any]:
    """An open `rosbags` reader of the bag at `path`, closed on leaving.

    Raises:
        UsageError: rosbags is not installed.
        MapImportError: the bag cannot be read.
    """
    try:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise UsageError(
            "ROS bags need rosbags; install it with `pip install 'mapapi[rosbag]'`"
        ) from None
    # a bag without message definitions (ROS 2 before Iron) decodes with these
    store = get_typestore(Stores.ROS2_HUMBLE if path.is_dir() else Stores.ROS1_NOETIC)
    try:
        reader = AnyReader([path], default_typestore=store)
        reader.open()
    except Exception as exc:  # rosbags has an error class per format and storage
        raise MapImportError(f"not a ROS bag rosbags can read: {exc}", source=str(path)) from exc
    try:
        yield reader
    finally:
        reader.close()


def _choose(connections: Iterable[Any], topics: Sequence[str], source: str) -> list[Any]:
    """The connections to read: those of `topics`, else of every supported type,
    and the TF topics in any case (they name frames).

    Raises:
        UsageError: a topic the bag lacks, or of a type not imported.
    """
    supported = (*msgs.POSE_TYPES, msgs.POINT_CLOUD, msgs.OCCUPANCY_GRID)
    everything = list(connections)
    by_topic = {c.topic: c.msgtype for c in everything}
    for topic in topics:
        msgtype = by_topic.get(topic)
        if msgtype is None:
            raise UsageError(
                f"{source} has no topic {topic!r}; it has {', '.join(sorted(by_topic)) or 'none'}"
            )
        if msgtype not in supported:
            raise UsageError(
                f"topic {topic} is of type {msgtype}, which is not imported; "
                f"expected one of {', '.join(supported)}"
            )
    chosen = []
    for connection in everything:
        wanted = connection.topic in topics if topics else connection.msgtype in supported
        if wanted or connection.msgtype in msgs.TF_TYPES:
            chosen.append(connection)
    return chosen
