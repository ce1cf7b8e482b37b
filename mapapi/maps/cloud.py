"""Point clouds as missions: points in memory, and their `PointCloudBlock` rows.

A cloud is split into blocks of at most `BLOCK_POINTS` points that lie close
together (the leaves of a k-d split: each cut halves a block along its longest
side), so every block's box is tight and a query for a region can skip the
blocks that miss it. A block stores little-endian float32 x, y, z, zlib-compressed
when that is smaller (`proto/mapapi/v1/maps.proto`). The order of the points
is not kept: a cloud is a set. Pure: numpy only, no open3d, no network.
"""

from __future__ import annotations

import zlib
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from mapapi.lookup.spatial import BBox
from mapapi.maps.errors import MapImportError
from mapapi.maps.schema import PointCloudBlock, box_to_pb

Points = npt.NDArray[np.float32]  # shape (n, 3)

BLOCK_POINTS = 4096  # 48 KiB of float32 xyz: small enough to replicate in one part
_WIRE = np.dtype("<f4")


def as_points(values: npt.ArrayLike) -> Points:
    """`values` as an (n, 3) float32 array.

    Raises:
        ValueError: not n rows of three numbers.
    """
    points = np.asarray(values, dtype=np.float32)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points must be n rows of x, y, z; got shape {points.shape}")
    return points


def moved(points: Points, matrix: npt.NDArray[np.float64]) -> Points:
    """`points` moved by the 4x4 rigid `matrix` (`alignment.pose_matrix`), as float32."""
    return (points @ matrix[:3, :3].T + matrix[:3, 3]).astype(np.float32)


def points_box(points: Points) -> BBox | None:
    """The box around `points` (None when there are none)."""
    if len(points) == 0:
        return None
    lo, hi = points.min(axis=0), points.max(axis=0)
    return BBox(*(float(v) for v in lo), *(float(v) for v in hi))


@dataclass(slots=True)
class PointCloud:
    """One mission's point cloud.

    Attributes:
        name: the mission's name, unique in a repository.
        robot: the robot that recorded it.
        frame: the frame its points are in.
        points: (n, 3) float32 positions in metres.
        dropped: points of the source left out because a coordinate was not finite.
        warnings: what its reader could not do, one line each (a bag's cloud that
            TF does not place: `mapapi.maps.bag_clouds`).
    """

    name: str
    robot: str = ""
    frame: str = ""
    points: Points = field(default_factory=lambda: np.zeros((0, 3), np.float32))
    dropped: int = 0
    warnings: list[str] = field(default_factory=list)

    def bbox(self) -> BBox | None:
        """The box around the points (None without points)."""
        return points_box(self.points)


def split_blocks(points: Points, size: int = BLOCK_POINTS) -> list[Points]:
    """Cut `points` into groups of at most `size` points that lie close together.

    Each cut splits a group at the median of its longest side, so the groups
    are the leaves of a k-d tree and all have between size/2 and size points.
    """
    if size < 1:
        raise ValueError(f"a block holds at least one point, not {size}")
    if len(points) == 0:
        return []
    leaves: list[Points] = []
    todo = [points]
    while todo:
        group = todo.pop()
        if len(group) <= size:
            leaves.append(group)
            continue
        axis = int(np.argmax(group.max(axis=0) - group.min(axis=0)))
        half = len(group) // 2
        order = np.argpartition(group[:, axis], half)
        todo += [group[order[half:]], group[order[:half]]]
    return leaves


def encode_points(points: Points) -> tuple[bytes, bool]:
    """The stored bytes of `points` and whether they are zlib-compressed (only
    when that is smaller: float coordinates often barely compress)."""
    raw = np.ascontiguousarray(points, dtype=_WIRE).tobytes()
    # level 1: float coordinates barely compress but for their zero bytes, which it
    # finds as well as level 6 (1 % larger on the room scan and the Intel log's scans)
    # in half the time
    packed = zlib.compress(raw, 1)
    return (packed, True) if len(packed) < len(raw) else (raw, False)


def block_to_pb(mission: str, points: Points) -> PointCloudBlock:
    """One block row: its points, count and box."""
    data, compressed = encode_points(points)
    message = PointCloudBlock(
        mission=mission, points=data, count=len(points), compressed=compressed
    )
    box = points_box(points)
    if box is not None:
        message.bbox.CopyFrom(box_to_pb(box))
    return message


def cloud_blocks(cloud: PointCloud, size: int = BLOCK_POINTS) -> list[PointCloudBlock]:
    """Every block row of a cloud."""
    return [block_to_pb(cloud.name, group) for group in split_blocks(cloud.points, size)]


def block_points(block: PointCloudBlock) -> Points:
    """The points of one stored block.

    Raises:
        MapImportError: the bytes do not hold `count` points.
    """
    data = zlib.decompress(block.points) if block.compressed else bytes(block.points)
    if len(data) != 12 * block.count:
        raise MapImportError(
            f"a block of mission {block.mission!r} holds {len(data)} bytes, "
            f"not {block.count} points of 12 bytes"
        )
    return np.frombuffer(data, dtype=_WIRE).reshape(-1, 3).astype(np.float32)


def cloud_from_blocks(
    name: str, robot: str, frame: str, blocks: Iterable[PointCloudBlock]
) -> PointCloud:
    """A stored mission's cloud from its block rows (in any order)."""
    groups = [block_points(b) for b in blocks]
    points = np.concatenate(groups) if groups else np.zeros((0, 3), np.float32)
    return PointCloud(name, robot, frame, points)
