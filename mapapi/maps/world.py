"""Where every mission lies in one shared `world` frame (issue 17 §1): the
computation behind `mapctl align`, with no sockets and no store.

Each mission's poses are in its own frame (a robot starts at the identity). The
world frame is one mission's, the anchor's. `align_world`:

1. sets aside a mission that repeats another (same robot, same content: its
   vertices and its own edges, `content_hash`), which would count the same
   measurements twice; it gets the frame of the one it repeats;
2. counts the inter-mission edges between every two missions; without an anchor
   given, the anchor is the mission with the most;
3. walks out from the anchor over pairs joined by at least `MIN_EDGES` edges,
   the best-joined first: each mission it reaches starts at the frame most of
   its edges to the mission that reached it agree on
   (`alignment.consensus_frame`), composed with that mission's start. Missions
   it never reaches stay unaligned and are reported;
4. optimises the reached missions together (`registration.optimise_missions`:
   gtsam, graduated non-convexity, the anchor's first pose held). The
   optimisation corrects drift, so it bends each trajectory: a mission's place
   is the rigid motion that best lays its stored trajectory on its optimised
   one (least squares over its vertices), taken relative to the anchor's, so
   the world is the anchor's own frame. Each place's covariance is that of the
   mission's first pose, from the marginals of the edges GNC kept.

The result depends on the graphs' content only, not on the order they come in.
"""

from __future__ import annotations

import hashlib
import struct
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from mapapi.core.errors import UsageError
from mapapi.lookup.spatial import BBox
from mapapi.maps.alignment import consensus_frame, invert, matrix_pose, pose_matrix
from mapapi.maps.graph import GraphEdge, MissionGraph
from mapapi.maps.registration import (
    MIN_EDGES,
    Residual,
    edges_among,
    links_between,
    optimise_missions,
)
from mapapi.maps.se3 import Pose, upper_index

WORLD = "world"
"""The shared frame's name."""

IDENTITY: Pose = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)


@dataclass(frozen=True)
class WorldFrame:
    """One mission's place in the world frame.

    Attributes:
        pose: its origin in the world frame (a vertex at P is at pose * P).
        covariance: the pose's 6x6 covariance, upper triangle (21 values, x first).
        linked: the missions whose kept edges tie it to the others.
        edges: its inter-mission edges GNC kept.
        duplicate_of: the mission it repeats, whose frame it takes ("" if none).
        content: its `content_hash`.
        bbox: once stored, the mission's box moved into the world frame.
        mission_chunk: once stored, the chunk of its mission row ("" if unknown).
    """

    mission: str
    pose: Pose
    covariance: tuple[float, ...]
    anchor: str
    linked: tuple[str, ...]
    edges: int
    duplicate_of: str
    content: str
    bbox: BBox | None = None
    mission_chunk: str = ""


@dataclass(frozen=True)
class WorldAlignment:
    """What `align_world` found: a frame per aligned mission (the anchor's the
    identity), the missions not joined to the anchor, and the optimisation's
    figures (as in `registration.Registration`; zero when only the anchor)."""

    anchor: str
    frames: dict[str, WorldFrame]
    unaligned: tuple[str, ...]
    edges: int
    inliers: int
    before: Residual
    after: Residual


def content_hash(graph: MissionGraph) -> str:
    """A hex SHA-256 of the mission's robot, vertices and own edges (ends by index,
    so a mission imported twice under two names hashes equal)."""
    digest = hashlib.sha256(graph.robot.encode() + b"\0")
    for index in sorted(graph.vertices):
        digest.update(struct.pack("<Q7d", index, *graph.vertices[index]))
    own = sorted(
        (e.source[1], e.target[1], e.kind.value, e.relative, e.information)
        for e in graph.edges
        if e.source[0] == e.target[0] == graph.name
    )
    for source, target, kind, relative, information in own:
        digest.update(
            struct.pack(f"<QQB7d{len(information)}d", source, target, kind, *relative, *information)
        )
    return digest.hexdigest()


def align_world(
    graphs: Sequence[MissionGraph], anchor: str | None = None, min_edges: int = MIN_EDGES
) -> WorldAlignment:
    """Place missions in one world frame (module docstring).

    Raises:
        UsageError: no mission; two missions share a name; the anchor is not
            among them; gtsam is missing (with two or more missions to join).
        RegistrationError: gtsam failed to optimise.
    """
    if not graphs:
        raise UsageError("no mission to align")
    by_name = {g.name: g for g in sorted(graphs, key=lambda g: g.name)}
    if len(by_name) != len(graphs):
        raise UsageError("a mission is named twice")
    if anchor is not None and anchor not in by_name:
        raise UsageError(f"no mission {anchor!r} to anchor the world frame")
    contents = {name: content_hash(g) for name, g in by_name.items()}
    originals: dict[str, str] = {}
    repeats: dict[str, str] = {}
    for name in sorted(by_name, key=lambda n: (n != anchor, n)):  # the anchor repeats none
        original = originals.setdefault(contents[name], name)
        if original != name:
            repeats[name] = original
    unique = [g for name, g in by_name.items() if name not in repeats]
    edges = edges_among(unique)
    counts = _pair_counts(edges)
    anchor = anchor or max(
        (g.name for g in unique), key=lambda n: (sum(c for p, c in counts.items() if n in p), n)
    )
    order, parents = _reach(anchor, counts, min_edges)
    starts = {anchor: np.eye(4)}
    for name in order[1:]:
        parent = parents[name]
        links = links_between(edges, by_name[parent], by_name[name])
        starts[name] = starts[parent] @ consensus_frame(links)[0]
    reached = [by_name[n] for n in order]
    if len(reached) > 1:
        solved = optimise_missions(reached, starts, covariance=True)
        # The optimisation bends each trajectory (drift corrected); a mission's
        # place is the rigid motion that best lays its stored trajectory on its
        # optimised one, and the world is the anchor's stored frame.
        world = invert(pose_matrix(solved.fitted[anchor]))
        poses = {n: matrix_pose(world @ pose_matrix(p)) for n, p in solved.fitted.items()}
        poses[anchor] = IDENTITY
        kept = solved.kept
        covariances = {n: _upper(c) for n, c in solved.covariances.items()}
        figures = (solved.edges, solved.inliers, solved.before, solved.after)
    else:
        poses, kept, covariances = {anchor: IDENTITY}, {}, {anchor: (0.0,) * 21}
        figures = (0, 0, Residual(0.0, 0.0), Residual(0.0, 0.0))
    frames = {}
    for name in order:
        linked = tuple(sorted(b if a == name else a for a, b in kept if name in (a, b)))
        own = sum(n for pair, n in kept.items() if name in pair)
        frames[name] = WorldFrame(
            name, poses[name], covariances[name], anchor, linked, own, "", contents[name]
        )
    for name, original in sorted(repeats.items()):
        if original in frames:
            frames[name] = WorldFrame(
                name,
                frames[original].pose,
                frames[original].covariance,
                anchor,
                (),
                0,
                original,
                contents[name],
            )
    unaligned = tuple(sorted(set(by_name) - set(frames)))
    return WorldAlignment(anchor, dict(sorted(frames.items())), unaligned, *figures)


def _pair_counts(edges: Sequence[GraphEdge]) -> dict[tuple[str, str], int]:
    """Inter-mission edges per (sorted) pair of missions."""
    counts: dict[tuple[str, str], int] = {}
    for edge in edges:
        a, b = edge.source[0], edge.target[0]
        if a != b:
            counts[(min(a, b), max(a, b))] = counts.get((min(a, b), max(a, b)), 0) + 1
    return counts


def _reach(
    anchor: str, counts: dict[tuple[str, str], int], min_edges: int
) -> tuple[list[str], dict[str, str]]:
    """The missions joined to the anchor, in the order they are reached (the
    strongest pair from those reached first, ties by name), and who reached each."""
    order, parents = [anchor], dict[str, str]()
    while True:
        best = None
        for (a, b), n in counts.items():
            if n < min_edges or (a in parents or a == anchor) == (b in parents or b == anchor):
                continue
            near, far = (a, b) if a in order else (b, a)
            if best is None or n > best[0] or (n == best[0] and far < best[2]):
                best = (n, near, far)
        if best is None:
            return order, parents
        order.append(best[2])
        parents[best[2]] = best[1]


def _upper(matrix: np.ndarray) -> tuple[float, ...]:
    """The upper triangle of a 6x6 matrix, row-major (`upper_index`'s order)."""
    values = [0.0] * 21
    for i in range(6):
        for j in range(i, 6):
            values[upper_index(i, j)] = float(matrix[i, j])
    return tuple(values)
