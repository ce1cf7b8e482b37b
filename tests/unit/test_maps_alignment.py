"""Pose matrices and the consensus alignment (`mapapi.maps.alignment`): pure
numpy, checked against frames known by construction."""

from __future__ import annotations

import math
import random

import numpy as np
import pytest

from mapapi.maps.alignment import (
    Link,
    candidates,
    consensus_frame,
    invert,
    matrix_pose,
    pose_matrix,
    residuals,
    support,
)
from mapapi.maps.se3 import Pose, compose


def rotation(axis: tuple[float, float, float], degrees: float, at: tuple[float, ...]) -> Pose:
    """The pose at `at` rotated by `degrees` about the unit `axis`."""
    half = math.radians(degrees) / 2
    s = math.sin(half)
    return (at[0], at[1], at[2], axis[0] * s, axis[1] * s, axis[2] * s, math.cos(half))


TRUE_FRAME = rotation((0.0, 0.6, 0.8), 40.0, (5.0, -3.0, 2.0))


class TestPoseMatrix:
    @pytest.mark.parametrize(
        "pose",
        [
            (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0),
            TRUE_FRAME,
            rotation((1.0, 0.0, 0.0), 179.9, (1.0, 2.0, 3.0)),  # each Shepperd branch
            rotation((0.0, 1.0, 0.0), 179.9, (-1.0, 0.0, 4.0)),
            rotation((0.0, 0.0, 1.0), 180.0, (0.0, -2.0, 0.0)),
        ],
    )
    def test_round_trip(self, pose: Pose) -> None:
        back = matrix_pose(pose_matrix(pose))
        sign = 1.0 if pose[6] >= 0 else -1.0  # q and -q are one rotation; we return w >= 0
        assert back[:3] == pytest.approx(pose[:3], abs=1e-12)
        assert [sign * v for v in back[3:]] == pytest.approx(pose[3:], abs=1e-12)
        assert back[6] >= 0

    def test_product_is_composition(self) -> None:
        a, b = TRUE_FRAME, rotation((1.0, 0.0, 0.0), 25.0, (0.5, 1.5, -2.0))
        assert matrix_pose(pose_matrix(a) @ pose_matrix(b)) == pytest.approx(compose(a, b))

    def test_invert_one_and_a_stack(self) -> None:
        m = pose_matrix(TRUE_FRAME)
        assert invert(m) @ m == pytest.approx(np.eye(4), abs=1e-12)
        stack = np.stack([m, pose_matrix(rotation((0.0, 0.0, 1.0), 90.0, (1.0, 0.0, 0.0)))])
        assert np.einsum("nij,njk->nik", invert(stack), stack) == pytest.approx(
            np.stack([np.eye(4)] * 2), abs=1e-12
        )

    def test_residuals_are_exact_for_small_and_large_angles(self) -> None:
        for degrees in (1e-7, 0.5, 90.0, 179.0):
            error = pose_matrix(rotation((0.0, 1.0, 0.0), degrees, (3.0, 4.0, 0.0)))
            metres, radians = residuals(error)
            assert float(metres) == pytest.approx(5.0)
            assert math.degrees(float(radians)) == pytest.approx(degrees, rel=1e-9)


def links_around(frame: Pose, count: int, rng: random.Random) -> list[Link]:
    """`count` exact links between reference poses and incoming poses whose
    frame in the reference's is `frame`."""
    out = []
    for k in range(count):
        g = rotation((0.0, 0.0, 1.0), rng.uniform(-180, 180), (k * 3.0, rng.uniform(-5, 5), 0.0))
        a = rotation((1.0, 0.0, 0.0), rng.uniform(-30, 30), (rng.uniform(-50, 50), k, 1.0))
        # measured: the incoming vertex seen from the reference vertex, g⁻¹ · T · a
        measured = invert(pose_matrix(g)) @ pose_matrix(frame) @ pose_matrix(a)
        out.append(Link(g, a, measured))
    return out


class TestConsensus:
    def test_each_exact_link_yields_the_frame(self) -> None:
        links = links_around(TRUE_FRAME, 5, random.Random(1))
        for found in candidates(links):
            assert found == pytest.approx(pose_matrix(TRUE_FRAME), abs=1e-9)

    def test_the_majority_wins_over_outliers(self) -> None:
        rng = random.Random(2)
        good = links_around(TRUE_FRAME, 6, rng)
        wrong = [
            links_around(rotation((0.0, 0.0, 1.0), rng.uniform(20, 340), (k * 40.0, 0, 0)), 1, rng)[
                0
            ]
            for k in range(5)
        ]
        links = [*wrong[:3], *good, *wrong[3:]]
        frame, votes = consensus_frame(links)
        assert votes == 6
        assert frame == pytest.approx(pose_matrix(TRUE_FRAME), abs=1e-9)
        assert list(support(links, candidates(links))) == [1, 1, 1, 6, 6, 6, 6, 6, 6, 1, 1]

    def test_no_links_is_an_error(self) -> None:
        with pytest.raises(ValueError, match="no inter-mission edges"):
            consensus_frame([])
