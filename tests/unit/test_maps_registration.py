"""Registering missions with gtsam (`mapapi.maps.registration`) on small
synthetic graphs whose answer is known: an incoming mission recorded in a frame
offset from the reference's, joined to it by exact inter-mission edges and by
outliers."""

from __future__ import annotations

import math
import random
import sys

import pytest

from mapapi.core.errors import UsageError
from mapapi.maps.alignment import invert, matrix_pose, pose_matrix
from mapapi.maps.graph import EdgeKind, GraphEdge, MissionGraph
from mapapi.maps.registration import (
    INSTALL_HINT,
    linked_missions,
    register_missions,
    require_gtsam,
)
from mapapi.maps.se3 import Pose, from_se2, isotropic_information, lift_information

INFO = isotropic_information(100.0, 10_000.0)


def yawed(x: float, y: float, z: float, yaw: float, roll: float = 0.0) -> Pose:
    """A pose at (x, y, z), turned by `yaw` about z after `roll` about x."""
    cy, sy, cr, sr = math.cos(yaw / 2), math.sin(yaw / 2), math.cos(roll / 2), math.sin(roll / 2)
    return (x, y, z, cy * sr, sy * sr, sy * cr, cy * cr)


def relative(a: Pose, b: Pose) -> Pose:
    """b seen from a: a⁻¹ · b."""
    return matrix_pose(invert(pose_matrix(a)) @ pose_matrix(b))


def in_frame(frame: Pose, pose: Pose) -> Pose:
    """`pose`, given in the reference frame, expressed in `frame` (frame⁻¹ · pose)."""
    return relative(frame, pose)


def chain(name: str, poses: list[Pose], info: tuple[float, ...] = INFO) -> MissionGraph:
    """A mission of `poses` with exact odometry."""
    graph = MissionGraph(name, name, f"{name}/odom", dict(enumerate(poses)))
    for i in range(len(poses) - 1):
        graph.edges.append(
            GraphEdge(
                (name, i),
                (name, i + 1),
                relative(poses[i], poses[i + 1]),
                info,
                EdgeKind.ODOMETRY,
            )
        )
    return graph


def link(
    owner: MissionGraph, source: tuple[str, int], target: tuple[str, int], measured: Pose
) -> None:
    owner.edges.append(GraphEdge(source, target, measured, INFO, EdgeKind.INTER_ROBOT))


TRUE_FRAME = yawed(6.0, -4.0, 3.0, 0.7, roll=0.2)
"""Where the incoming mission's frame lies in the reference's."""


def scene(outliers: int = 3, seed: int = 0) -> tuple[MissionGraph, MissionGraph, int]:
    """A ground mission, an incoming one stored in its own frame, and the
    number of exact inter-mission edges between them (both own some)."""
    ground_truth = [yawed(2.0 * i, 3 * math.sin(i / 4), 0.0, 0.15 * i) for i in range(15)]
    air_truth = [
        yawed(2.0 * j + 1, 3 * math.sin(j / 4) + 0.5, 4.0, 0.15 * j + 0.3) for j in range(15)
    ]
    ground = chain("ground", ground_truth)
    air = chain("air", [in_frame(TRUE_FRAME, p) for p in air_truth])
    exact = 0
    for j in range(0, 15, 2):
        link(ground, ("ground", j), ("air", j), relative(ground_truth[j], air_truth[j]))
        exact += 1
    for j in range(1, 14, 3):  # edges the incoming mission owns point the other way
        link(air, ("air", j), ("ground", j + 1), relative(air_truth[j], ground_truth[j + 1]))
        exact += 1
    rng = random.Random(seed)
    for _ in range(outliers):  # wrong place recognitions: far off in place and heading
        i, j = rng.randrange(15), rng.randrange(15)
        wrong = yawed(rng.uniform(10, 30), rng.uniform(-20, 20), 0.0, rng.uniform(1.0, 2.5))
        link(ground, ("ground", i), ("air", j), wrong)
    return ground, air, exact


class TestRegister:
    def test_the_known_frame_is_found_and_outliers_are_dropped(self) -> None:
        pytest.importorskip("gtsam")
        ground, air, exact = scene(outliers=3)
        result = register_missions(ground, [air])
        assert result.reference == "ground"
        assert list(result.frames) == ["air"]
        assert pose_matrix(result.frames["air"]) == pytest.approx(pose_matrix(TRUE_FRAME), abs=1e-6)
        assert (result.edges, result.inliers) == (exact + 3, exact)
        assert result.before.metres < 1e-9  # the consensus start is exact already
        # GNC first weighs the outliers in, then out; LM stops within its tolerance
        assert result.after.metres < 1e-3
        assert result.after.degrees < 1e-2

    def test_edge_order_does_not_change_the_answer(self) -> None:
        pytest.importorskip("gtsam")
        ground, air, _ = scene(outliers=2, seed=5)
        first = register_missions(ground, [air])
        for graph in (ground, air):
            random.Random(9).shuffle(graph.edges)
        assert register_missions(ground, [air]) == first

    def test_a_planar_graph_lifted_from_2d_registers(self) -> None:
        pytest.importorskip("gtsam")
        frame = from_se2(3.0, -2.0, 0.9)
        info = lift_information((100.0, 0.0, 0.0, 100.0, 0.0, 1000.0))  # z, roll, pitch: none
        ground_truth = [from_se2(1.5 * i, math.cos(i / 3), 0.2 * i) for i in range(10)]
        air_truth = [from_se2(1.5 * i + 0.5, math.cos(i / 3) + 1, 0.2 * i - 0.4) for i in range(10)]
        ground = chain("g2d", ground_truth, info)
        air = chain("a2d", [in_frame(frame, p) for p in air_truth], info)
        for i in range(0, 10, 2):
            ground.edges.append(
                GraphEdge(
                    ("g2d", i),
                    ("a2d", i),
                    relative(ground_truth[i], air_truth[i]),
                    info,
                    EdgeKind.INTER_ROBOT,
                )
            )
        result = register_missions(ground, [air])
        assert result.frames["a2d"] == pytest.approx(frame, abs=1e-6)
        assert result.inliers == 5

    def test_too_few_shared_edges_are_refused(self) -> None:
        pytest.importorskip("gtsam")
        ground, air, _ = scene(outliers=0)
        lonely = chain("lonely", [yawed(0.0, float(i), 0.0, 0.0) for i in range(3)])
        with pytest.raises(UsageError, match="'lonely' shares 0 edges with 'ground'"):
            register_missions(ground, [air, lonely])

    def test_bad_input_is_refused(self) -> None:
        pytest.importorskip("gtsam")
        ground, air, _ = scene(outliers=0)
        with pytest.raises(UsageError, match="no mission to register"):
            register_missions(ground, [])
        with pytest.raises(UsageError, match="named twice: ground"):
            register_missions(ground, [ground])
        link(air, ("air", 3), ("ground", 99), yawed(0.0, 0.0, 0.0, 0.0))
        with pytest.raises(UsageError, match="vertex 99 of 'ground'"):
            register_missions(ground, [air])

    def test_an_information_matrix_that_is_not_positive_is_refused(self) -> None:
        pytest.importorskip("gtsam")
        ground, air, _ = scene(outliers=0)
        bad = list(INFO)
        bad[1] = 500.0  # x-y coupling larger than either axis
        edge = air.edges[0]
        air.edges[0] = GraphEdge(edge.source, edge.target, edge.relative, tuple(bad), edge.kind)
        with pytest.raises(UsageError, match="not positive definite"):
            register_missions(ground, [air])

    def test_without_gtsam_the_error_says_how_to_install_it(
        self, monkeypatch: pytest.MonkeyPatch
    ) -> None:
        monkeypatch.setitem(sys.modules, "gtsam", None)  # import gtsam raises ImportError
        with pytest.raises(UsageError, match=r"pip install 'mapapi\[registration\]'") as err:
            require_gtsam()
        assert INSTALL_HINT in str(err.value)
        assert err.value.exit_code == 2


class TestLinkedMissions:
    def test_counts_the_missions_its_own_edges_reach(self) -> None:
        ground, air, _ = scene(outliers=3)
        assert linked_missions(ground) == ["air"]  # 8 exact + 3 outliers, owned by ground
        assert linked_missions(air) == ["ground"]  # the 5 air owns
        assert linked_missions(air, min_edges=6) == []
        assert linked_missions(ground, among={"other"}) == []
