"""The TF tree of a bag (`mapapi.maps.tf_tree`): interpolation in time, paths
composed along the tree in either direction, and the refusals that name frames."""

from __future__ import annotations

import math

import pytest

from mapapi.maps.se3 import IDENTITY, Pose, compose, inverse, yaw
from mapapi.maps.tf_tree import TOLERANCE, NoTfPath, TfOutOfRange, TfTree, interpolate


def turned(x: float, y: float, z: float, degrees: float) -> Pose:
    """A pose at (x, y, z) turned `degrees` about z."""
    half = math.radians(degrees) / 2
    return (x, y, z, 0.0, 0.0, math.sin(half), math.cos(half))


def robot() -> TfTree:
    """odom -> base_link at t 10 and 20 (moving 2 m along x, turning 90 degrees),
    base_link -> lidar static (0.5 m ahead, 0.3 m up), base_link -> camera static."""
    tree = TfTree()
    tree.add("odom", "base_link", 10.0, turned(0.0, 0.0, 0.0, 0.0), static=False)
    tree.add("odom", "base_link", 20.0, turned(2.0, 0.0, 0.0, 90.0), static=False)
    tree.add("base_link", "lidar", 0.0, turned(0.5, 0.0, 0.3, 0.0), static=True)
    tree.add("base_link", "camera", 0.0, turned(0.0, 0.2, 0.1, -90.0), static=True)
    return tree


class TestInterpolation:
    def test_translation_is_linear_and_rotation_a_slerp(self) -> None:
        pose = robot().lookup("odom", "base_link", 12.5)
        assert pose[:3] == pytest.approx((0.5, 0.0, 0.0))
        assert math.degrees(yaw(pose)) == pytest.approx(22.5)
        assert sum(v * v for v in pose[3:]) == pytest.approx(1.0)

    def test_the_ends_are_the_transforms_themselves(self) -> None:
        tree = robot()
        assert tree.lookup("odom", "base_link", 10.0) == pytest.approx(turned(0, 0, 0, 0))
        assert tree.lookup("odom", "base_link", 20.0) == pytest.approx(turned(2, 0, 0, 90))

    def test_slerp_takes_the_shorter_arc(self) -> None:
        a, b = turned(0, 0, 0, 170.0), turned(0, 0, 0, -170.0)
        flipped = (*b[:3], *(-v for v in b[3:]))  # the same rotation, written -q
        for end in (b, flipped):
            assert math.degrees(yaw(interpolate(a, end, 0.5))) % 360 == pytest.approx(180.0)

    def test_transforms_added_out_of_order_are_sorted(self) -> None:
        tree = TfTree()
        tree.add("odom", "base_link", 20.0, turned(2, 0, 0, 0), static=False)
        tree.add("odom", "base_link", 10.0, turned(0, 0, 0, 0), static=False)
        assert tree.lookup("odom", "base_link", 15.0)[:3] == pytest.approx((1.0, 0.0, 0.0))


class TestPaths:
    def test_a_chain_composes_dynamic_then_static(self) -> None:
        pose = robot().lookup("odom", "lidar", 20.0)
        # at t 20 the robot is at (2, 0) facing +y: the lidar 0.5 m ahead is at (2, 0.5)
        assert pose == pytest.approx(turned(2.0, 0.5, 0.3, 90.0))

    def test_the_inverse_direction_is_the_inverse_pose(self) -> None:
        tree = robot()
        there = tree.lookup("odom", "lidar", 15.0)
        back = tree.lookup("lidar", "odom", 15.0)
        assert compose(back, there) == pytest.approx(IDENTITY, abs=1e-12)
        assert back == pytest.approx(inverse(there))

    def test_siblings_meet_at_their_common_parent(self) -> None:
        pose = robot().lookup("camera", "lidar", 13.0)  # the same at any time: both static
        want = compose(inverse(turned(0.0, 0.2, 0.1, -90.0)), turned(0.5, 0.0, 0.3, 0.0))
        assert pose == pytest.approx(want)

    def test_a_frame_in_itself_is_the_identity(self) -> None:
        assert TfTree().lookup("anywhere", "anywhere", 1.0) == IDENTITY

    def test_static_links_hold_at_any_time(self) -> None:
        tree = robot()
        for stamp in (-1e9, 0.0, 1e9):
            assert tree.lookup("base_link", "lidar", stamp) == turned(0.5, 0.0, 0.3, 0.0)

    def test_a_second_parent_is_ignored(self) -> None:
        tree = robot()
        tree.add("map", "lidar", 0.0, turned(9, 9, 9, 0), static=True)
        assert tree.parent("lidar") == "base_link"
        assert tree.lookup("base_link", "lidar", 0.0) == turned(0.5, 0.0, 0.3, 0.0)


class TestRefusals:
    def test_frames_of_two_trees_have_no_path(self) -> None:
        tree = robot()
        tree.add("map", "gps", 0.0, IDENTITY, static=True)
        with pytest.raises(
            NoTfPath,
            match="no TF path from lidar to gps: lidar is in the tree of odom, gps in that of map",
        ) as caught:
            tree.lookup("gps", "lidar", 15.0)
        assert (caught.value.target, caught.value.source) == ("gps", "lidar")
        with pytest.raises(NoTfPath, match="from lidar to nowhere"):
            tree.lookup("nowhere", "lidar", 15.0)

    @pytest.mark.parametrize("stamp", [10.0 - 2 * TOLERANCE, 20.0 + 2 * TOLERANCE])
    def test_a_stamp_outside_the_transforms_is_refused(self, stamp: float) -> None:
        with pytest.raises(
            TfOutOfRange,
            match=r"TF odom -> base_link is known from 10\.000 "
            r"to 20\.000 s, not at",
        ) as caught:
            robot().lookup("odom", "lidar", stamp)
        assert (caught.value.parent, caught.value.child) == ("odom", "base_link")
        assert caught.value.stamp == stamp

    def test_within_the_tolerance_the_nearest_transform_holds(self) -> None:
        tree = robot()
        early = tree.lookup("odom", "base_link", 10.0 - TOLERANCE / 2)
        late = tree.lookup("odom", "base_link", 20.0 + TOLERANCE / 2)
        assert (early, late) == (turned(0, 0, 0, 0), turned(2, 0, 0, 90))

    def test_the_tolerance_is_a_choice(self) -> None:
        tree = TfTree(tolerance=0.0)
        tree.add("odom", "base_link", 10.0, IDENTITY, static=False)
        assert tree.lookup("odom", "base_link", 10.0) == IDENTITY
        with pytest.raises(TfOutOfRange, match=r"more than 0\.0 s outside"):
            tree.lookup("odom", "base_link", 10.001)
