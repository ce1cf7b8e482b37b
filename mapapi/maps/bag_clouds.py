"""A bag's point cloud topic, its scans placed through TF in the trajectory's
frame (issue 17: "TF gives frames").

A `sensor_msgs/PointCloud2` is given in its header's frame, often a sensor's
(`lidar`), which moves with the robot. Each message is kept as read, with its
stamp (its header's, or the time the bag recorded it when that is zero) and
its frame; once the whole bag is read, so the TF tree holds the transforms
both before and after every scan, `BagCloud.placed` moves each scan into the
trajectory's frame (`odom`) at its stamp (`mapapi.maps.tf_tree`), so the
cloud's points and the trajectory's poses line up.

When TF joins no path from the cloud's frame to the trajectory's, the points
stay in their own frame, as they were before TF was read, and a warning says
so; a scan stamped outside the transforms of its path (`tf_tree.TOLERANCE`)
is left out, and a warning counts them: its place would be a guess.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mapapi.maps import bag_messages as msgs
from mapapi.maps.alignment import pose_matrix
from mapapi.maps.cloud import Points, moved
from mapapi.maps.se3 import IDENTITY
from mapapi.maps.tf_tree import NoTfPath, TfOutOfRange, TfTree


@dataclass(frozen=True)
class _Scan:
    """One message's points, as given, with its stamp and frame."""

    stamp: float
    frame: str
    points: Points


@dataclass(frozen=True)
class Placed:
    """A cloud topic's points, all in `frame`, and what could not be done.

    Attributes:
        warnings: one line each, naming the topic and the frames.
    """

    points: Points
    frame: str
    warnings: list[str]


@dataclass
class BagCloud:
    """One point cloud topic's scans as they are read.

    Attributes:
        topic: the bag's topic.
        name: the mission's name.
        dropped: points left out because a coordinate was not finite.
    """

    topic: str
    name: str
    scans: list[_Scan] = field(default_factory=list)
    dropped: int = 0

    @property
    def frame(self) -> str:
        """The frame of its first message ("" when it has none)."""
        return self.scans[0].frame if self.scans else ""

    def add(self, message: Any, received: float) -> None:
        """Keep a `sensor_msgs/PointCloud2` message's finite points.

        Raises:
            ValueError: the message holds no float x, y, z (`bag_messages.cloud_points`).
        """
        points, dropped = msgs.cloud_points(message)
        stamp = msgs.stamp_seconds(message.header.stamp) or received
        self.scans.append(_Scan(stamp, msgs.frame_name(message.header.frame_id), points))
        self.dropped += dropped

    def placed(self, tf: TfTree, target: str | None) -> Placed:
        """Its points in frame `target` (see the module docstring); with no
        `target` (no trajectory read), in their own frame."""
        if target is None or all(scan.frame == target for scan in self.scans):
            return self._as_given()
        kept = f"its points stay in {self.frame or 'no frame'}, as its messages give them"
        if any(not scan.frame for scan in self.scans):  # TF cannot place what names no frame
            return self._as_given(f"topic {self.topic}: a message names no frame; {kept}")
        parts, refused = [], []
        for scan in self.scans:
            try:
                pose = tf.lookup(target, scan.frame, scan.stamp)
            except NoTfPath as exc:
                return self._as_given(f"topic {self.topic}: {exc}; {kept}")
            except TfOutOfRange as exc:
                refused.append(exc)
                continue
            same = pose == IDENTITY  # a scan in the target frame already
            parts.append(scan.points if same else moved(scan.points, pose_matrix(pose)))
        warnings = []
        if refused:
            warnings.append(
                f"topic {self.topic}: {len(refused)} of {len(self.scans)} scans left out, "
                f"TF cannot place them in {target} at their time ({refused[0]})"
            )
        return Placed(_joined(parts), target, warnings)

    def _as_given(self, *warnings: str) -> Placed:
        """Every point as its message gives it, in the first message's frame."""
        return Placed(_joined(s.points for s in self.scans), self.frame, list(warnings))


def _joined(parts: Iterable[Points]) -> Points:
    found = list(parts)
    return np.concatenate(found) if found else np.zeros((0, 3), np.float32)
