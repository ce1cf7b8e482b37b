"""Placing missions in one world frame (`mapapi.maps.world.align_world`) on small
synthetic missions whose frames are known: exact edges (and outliers) between
them, a mission reached only through another, one joined to none, and one
imported twice."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from mapapi.core.errors import UsageError
from mapapi.maps.alignment import pose_matrix
from mapapi.maps.graph import MissionGraph
from mapapi.maps.se3 import Pose
from mapapi.maps.world import IDENTITY, align_world, content_hash
from tests.unit.test_maps_registration import chain, in_frame, link, relative, yawed

pytest.importorskip("gtsam", reason="the registration extra (make test installs it)")

TRUTH = {"b": yawed(6.0, -4.0, 0.0, 0.7), "c": yawed(-5.0, 8.0, 0.0, -1.1)}
"""Where missions b and c lie in a's frame (the world, a anchoring it)."""


def _path(offset: float) -> list[Pose]:
    return [yawed(2.0 * i, 3 * math.sin(i / 4) + offset, 0.0, 0.15 * i) for i in range(16)]


def _scene() -> list[MissionGraph]:
    """a, b, c driving near each other (a-b and b-c joined by exact edges and one
    outlier each; a and c by none), and d, far away, joined to no one."""
    truth = {"a": _path(0.0), "b": _path(0.6), "c": _path(1.2)}
    graphs = {
        name: chain(name, [in_frame(TRUTH.get(name, IDENTITY), p) for p in poses])
        for name, poses in truth.items()
    }
    for near, far in (("a", "b"), ("b", "c")):
        for i in range(0, 16, 3):
            link(graphs[near], (near, i), (far, i), relative(truth[near][i], truth[far][i]))
        link(graphs[near], (near, 1), (far, 9), yawed(30.0, -20.0, 0.0, 2.0))  # a wrong match
    graphs["d"] = chain("d", _path(50.0))
    return list(graphs.values())


def _close(a: Pose, b: Pose) -> bool:
    return bool(np.allclose(pose_matrix(a), pose_matrix(b), atol=1e-4))


def test_missions_joined_directly_or_through_another_get_their_true_frames() -> None:
    found = align_world(_scene(), anchor="a")

    assert found.anchor == "a"
    assert set(found.frames) == {"a", "b", "c"}
    assert _close(found.frames["a"].pose, IDENTITY)
    assert _close(found.frames["b"].pose, TRUTH["b"])
    assert _close(found.frames["c"].pose, TRUTH["c"])  # reached through b only
    assert found.unaligned == ("d",)
    assert (found.edges, found.inliers) == (14, 12)  # the two wrong matches weighed out
    assert found.frames["c"].linked == ("b",)
    assert found.frames["b"].linked == ("a", "c")
    assert found.after.metres < 1e-4


def test_the_best_joined_mission_anchors_by_default_and_order_does_not_matter() -> None:
    forward = align_world(_scene())
    backward = align_world(list(reversed(_scene())))

    assert forward.anchor == backward.anchor == "b"  # joined to both others
    assert forward.frames == backward.frames


def test_a_mission_imported_twice_takes_the_frame_of_the_first() -> None:
    scene = _scene()
    c = next(g for g in scene if g.name == "c")
    again = replace(
        c,
        name="c-again",
        vertices=dict(c.vertices),
        edges=[
            replace(e, source=("c-again", e.source[1]), target=("c-again", e.target[1]))
            for e in c.edges
        ],
    )
    assert content_hash(again) == content_hash(c)

    found = align_world([*scene, again], anchor="a")

    assert found.frames["c-again"].duplicate_of == "c"
    assert found.frames["c-again"].pose == found.frames["c"].pose
    assert found.inliers == 12  # its edges were not counted a second time


def test_an_anchor_alone_is_the_world_and_bad_requests_say_why() -> None:
    lone = align_world([chain("solo", _path(0.0))])
    assert lone.frames["solo"].pose == IDENTITY
    assert (lone.edges, lone.unaligned) == (0, ())
    with pytest.raises(UsageError, match="no mission 'x' to anchor"):
        align_world(_scene(), anchor="x")
    with pytest.raises(UsageError, match="no mission to align"):
        align_world([])
