"""Laser missions: a trajectory whose poses each took a 2D laser scan.

A `LaserMission` is a pose graph (`MissionGraph`) and, per vertex, the points of
the scan taken there. Its rows are the graph's (tiled as any graph's) and one
`PointCloudBlock` per scan, which names its vertex (`PointCloudBlock.vertex`).
The points are stored in the mission's frame, as the scan's pose placed them:
every reader of clouds (`export` to PLY, `plot`, `query-bbox`, the spatial index
by each block's box) then reads them as it reads any cloud, and the vertex link
lets a later step move a scan with its pose. Pure: numpy only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from mapapi.lookup.spatial import BBox
from mapapi.maps.cloud import Points, block_to_pb, points_box
from mapapi.maps.graph import MissionGraph
from mapapi.maps.schema import PointCloudBlock

FIELD_OF_VIEW = math.pi
"""What a CARMEN front laser spans: 180 degrees, from the right (-90) to the left."""


def beam_angles(count: int) -> np.ndarray:
    """The bearing of each of `count` beams over `FIELD_OF_VIEW`, first at -90°.

    A FLASER record lists ranges, not angles: 180 or 360 beams are taken 1° or
    0.5° apart from -90° (the SICK's resolutions), 181 or 361 at the same steps
    with both ends included; any other count spreads evenly the same way.
    """
    step = FIELD_OF_VIEW / (count if count % 2 == 0 else max(count - 1, 1))
    return -0.5 * FIELD_OF_VIEW + step * np.arange(count, dtype=np.float64)


def project_scan(
    ranges: np.ndarray, angles: np.ndarray, pose: tuple[float, float, float], max_range: float
) -> Points:
    """The points of a scan taken at the planar `pose` (x, y, theta), in the
    frame the pose is given in, float32 with z = 0; ranges not in (0, max_range)
    are no returns and give no point."""
    keep = (ranges > 0.0) & (ranges < max_range)
    reach, bearing = ranges[keep], angles[keep] + pose[2]
    points = np.zeros((len(reach), 3), dtype=np.float32)
    points[:, 0] = pose[0] + reach * np.cos(bearing)
    points[:, 1] = pose[1] + reach * np.sin(bearing)
    return points


@dataclass(frozen=True)
class Correction:
    """How scan matching (`mapapi.maps.scan_match`) corrected a laser mission.

    Attributes:
        keyframes: the scans matched to the map of those before them.
        largest: metres between a corrected pose and its odometry, at most.
    """

    keyframes: int
    largest: float


@dataclass(slots=True)
class LaserMission(MissionGraph):
    """A pose graph whose vertices took laser scans (see the module docstring):
    a `MissionGraph`, so every graph step (checks, tiles, renaming) applies.

    Attributes:
        scans: vertex index -> the points its scan gave, in the mission's frame
            (no entry for a pose without scan, or a scan without a return).
        correction: how scan matching moved its poses (None: as the log gave them).
    """

    scans: dict[int, Points] = field(default_factory=dict)
    correction: Correction | None = None

    def point_count(self) -> int:
        """How many scan points it holds."""
        return sum(len(p) for p in self.scans.values())

    def bbox(self) -> BBox | None:
        """The box around its poses and its scans' points."""
        # not super(): a slots dataclass is a new class, which zero-argument super() misses
        boxes = [MissionGraph.bbox(self), *map(points_box, self.scans.values())]
        found = [b for b in boxes if b is not None]
        return BBox.enclosing(found) if found else None


def scan_blocks(mission: LaserMission) -> list[PointCloudBlock]:
    """One block row per scan, naming its vertex, in vertex order."""
    blocks = []
    for index in sorted(mission.scans):
        block = block_to_pb(mission.name, mission.scans[index])
        block.vertex = index
        blocks.append(block)
    return blocks
