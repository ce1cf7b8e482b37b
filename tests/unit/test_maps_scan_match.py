"""Scan matching (mapapi.maps.scan_match): a drifting odometry corrected by its
own laser scans, on a simulated building whose true poses are known and on the
Intel log's head."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest

from mapapi.core.errors import UsageError
from mapapi.maps.carmen import read_carmen
from mapapi.maps.laser import beam_angles
from mapapi.maps.scan_match import (
    RESOLUTION,
    LikelihoodField,
    match_mission,
    match_scans,
    place,
    seen_from,
)
from mapapi.maps.se3 import yaw
from mapapi.maps.source import read_source

SAMPLES = Path(__file__).resolve().parents[2] / "sample_maps"
LOG = SAMPLES / "laser_logs" / "intel-head.clf.bz2"

# A floor of 24 x 12 m: outer walls, two inner walls with doors, a pillar.
WALLS = np.array(
    [
        (0, 0, 24, 0),
        (24, 0, 24, 12),
        (24, 12, 0, 12),
        (0, 12, 0, 0),
        (8, 0, 8, 5),
        (8, 7, 8, 12),
        (16, 0, 16, 4),
        (16, 6, 16, 12),
        (4, 9, 5, 9),
        (5, 9, 5, 10),
        (20, 3, 21, 3),
        (21, 3, 21, 4),
    ],
    dtype=np.float64,
)


def cast(pose: np.ndarray, angles: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """The (m, 2) points a laser at `pose` sees of `WALLS`, in its own frame,
    with 1 cm of range noise."""
    bearing = angles + pose[2]
    d = np.stack([np.cos(bearing), np.sin(bearing)], axis=1)  # (b, 2)
    a, b = WALLS[:, :2], WALLS[:, 2:]
    e = b - a  # (w, 2)
    w = a - pose[:2]  # (w, 2)
    denominator = d[:, None, 0] * e[None, :, 1] - d[:, None, 1] * e[None, :, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (w[None, :, 0] * e[None, :, 1] - w[None, :, 1] * e[None, :, 0]) / denominator
        u = (w[None, :, 0] * d[:, None, 1] - w[None, :, 1] * d[:, None, 0]) / denominator
    hit = (t > 0) & (u >= 0) & (u <= 1)
    reach = np.where(hit, t, np.inf).min(axis=1)
    keep = reach < 30.0
    reach = reach[keep] + rng.normal(0, 0.01, keep.sum())
    return np.stack([reach * np.cos(angles[keep]), reach * np.sin(angles[keep])], axis=1)


def tour(steps: int = 400) -> np.ndarray:
    """True poses: through both doors to the far room, around it, and back."""
    stops = np.array([(3, 6), (12, 6), (20, 5), (22, 9), (18, 10), (12, 6), (3, 3), (3, 6)])
    lengths = np.hypot(*np.diff(stops, axis=0).T)
    along = np.linspace(0, lengths.sum(), steps)
    ends = np.concatenate([[0], np.cumsum(lengths)])
    x = np.interp(along, ends, stops[:, 0])
    y = np.interp(along, ends, stops[:, 1])
    heading = np.unwrap(np.arctan2(np.gradient(y), np.gradient(x)))
    return np.stack([x, y, heading], axis=1)


def drift(truth: np.ndarray) -> np.ndarray:
    """Odometry of the true poses: 3 % long and 2 degrees of heading per metre."""
    odometry = [truth[0].copy()]
    for before, after in itertools.pairwise(truth):
        c, s = math.cos(before[2]), math.sin(before[2])
        dx, dy = after[0] - before[0], after[1] - before[1]
        forward, side = c * dx + s * dy, -s * dx + c * dy
        turn = after[2] - before[2] + math.radians(2.0) * math.hypot(forward, side)
        last = odometry[-1]
        c, s = math.cos(last[2]), math.sin(last[2])
        forward, side = forward * 1.03, side * 1.03
        odometry.append(
            np.array(
                [last[0] + c * forward - s * side, last[1] + s * forward + c * side, last[2] + turn]
            )
        )
    return np.array(odometry)


@pytest.fixture(scope="module")
def building() -> tuple[np.ndarray, np.ndarray, list[np.ndarray | None]]:
    truth = tour()
    rng = np.random.default_rng(3)
    angles = beam_angles(180)
    return truth, drift(truth), [cast(p, angles, rng) for p in truth]


def error(poses: np.ndarray, truth: np.ndarray) -> np.ndarray:
    return np.hypot(*(poses[:, :2] - truth[:, :2]).T)


class TestMatching:
    def test_the_scans_undo_the_odometrys_drift(self, building: tuple) -> None:
        truth, odometry, scans = building
        assert error(odometry, truth).max() > 2.0  # what the wheels alone give

        matched = match_scans(odometry, scans)

        assert error(matched.poses, truth).max() < 0.15
        assert abs(math.remainder(matched.poses[-1, 2] - truth[-1, 2], 2 * math.pi)) < 0.02
        assert matched.poses[0].tolist() == odometry[0].tolist()
        assert 50 < matched.keyframes < len(truth)
        assert matched.largest == pytest.approx(error(matched.poses, odometry).max())

    def test_poses_without_scans_follow_the_odometry(self, building: tuple) -> None:
        _, odometry, _ = building
        matched = match_scans(odometry, [None] * len(odometry))
        assert np.allclose(matched.poses, odometry)
        assert matched.keyframes == 0

    def test_progress_reaches_the_end(self, building: tuple) -> None:
        _, odometry, scans = building
        seen: list[tuple[int, int]] = []
        match_scans(odometry[:50], scans[:50], lambda done, total: seen.append((done, total)))
        assert seen[0] == (0, 50)
        assert seen[-1] == (50, 50)


class TestField:
    def test_a_point_is_likeliest_on_its_cell(self) -> None:
        field = LikelihoodField((0.0, 0.0), half=5.0)
        field.add(np.array([[1.0, 1.0]]))
        at = np.array([[1.0, 1.0, 0.0], [1.0 + 2 * RESOLUTION, 1.0, 0.0], [3.0, 3.0, 0.0]])
        scores = field.score(np.zeros((1, 2)), at, smooth=True)
        assert scores[0] > scores[1] > scores[2] == 0.0

    def test_it_grows_to_take_points_far_off(self) -> None:
        field = LikelihoodField((0.0, 0.0), half=5.0)
        far = np.array([[-80.0, 120.0], [200.0, -3.0]])
        field.add(far)
        for smooth in (False, True):
            scores = field.score(
                np.zeros((1, 2)), np.array([[*p, 0.0] for p in far]), smooth=smooth
            )
            assert (scores > 0.5).all()  # a point sits within half a cell of its peak


class TestLaserMission:
    def test_each_scan_moves_with_its_corrected_pose(self) -> None:
        raw = read_carmen(LOG)
        laser = read_carmen(LOG)

        correction = match_mission(laser)

        assert correction.keyframes > 100
        assert laser.correction == correction
        assert laser.edges == raw.edges  # what the wheels measured stays
        for index in list(raw.scans)[::97]:
            before, after = raw.vertices[index], laser.vertices[index]
            old = np.array([before[0], before[1], yaw(before)])
            new = np.array([after[0], after[1], yaw(after)])
            local = seen_from(raw.scans[index][:, :2].astype(np.float64), old)
            assert np.allclose(laser.scans[index][:, :2], place(local, new), atol=1e-4)

    def test_the_intel_heads_walls_are_crisper(self) -> None:
        """The scans' points pile onto fewer 10 cm cells once the poses follow
        the walls: one wall seen from many poses, not many smeared copies."""
        raw = read_carmen(LOG)
        laser = read_carmen(LOG)
        match_mission(laser)

        def cells(mission: object) -> int:
            points = np.concatenate(list(mission.scans.values()))[:, :2]  # type: ignore[attr-defined]
            return len(np.unique(np.floor(points / 0.1).astype(np.int64), axis=0))

        assert cells(laser) < 0.7 * cells(raw)

    def test_only_laser_logs_are_scan_matched(self) -> None:
        intel = read_source(LOG, scan_match=True)
        assert intel[0].correction is not None  # type: ignore[union-attr]
        with pytest.raises(UsageError, match="--scan-match applies to laser logs"):
            read_source(SAMPLES / "pose_graphs" / "intel.g2o", scan_match=True)
