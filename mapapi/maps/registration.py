"""Register missions against a reference mission: a robust pose-graph
optimisation over their vertices, their own edges and the inter-mission edges,
solved by gtsam (the optional `registration` extra; no solver of our own).

Each mission's poses are in its own frame (a robot starts at the identity).
`register_missions(reference, incoming)` finds where each incoming mission's
frame lies in the reference's:

1. each incoming mission starts at the frame most of its edges to the
   reference agree on (`mapapi.maps.alignment.consensus_frame`);
2. one factor graph holds every vertex of the missions (reference as stored,
   the others moved into its frame), a tight prior on the reference's first
   vertex (the gauge), and a between-factor per edge among them, weighted by
   the edge's information matrix;
3. gtsam's graduated non-convexity (GNC, truncated least squares, over
   Levenberg-Marquardt) optimises it: odometry is trusted, while loop closures
   and inter-mission edges may be outliers (wrong place recognitions) and are
   weighted out when they disagree with the rest, as Kimera-Multi does.

A mission's frame is then the transform taking its stored first vertex to its
optimised one. The quality figures are the RMS residual of the inter-mission
edges GNC kept, at the starting alignment and after the optimisation.
No sockets here: the bench (`mapbench.registration`) moves the missions.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from mapapi.core.errors import MapError, UsageError
from mapapi.maps.alignment import Link, consensus_frame, invert, matrix_pose, pose_matrix, residuals
from mapapi.maps.graph import EdgeKind, GraphEdge, MissionGraph, VertexKey
from mapapi.maps.se3 import Pose, upper_index

INSTALL_HINT = "pip install 'mapapi[registration]'"

MIN_EDGES = 3
"""Inter-mission edges an incoming mission needs with the reference (fewer
cannot fix its frame against outliers)."""

INLIER_PROBABILITY = 0.99
"""GNC keeps an edge whose residual a correct measurement would exceed with
at most 1 % probability (the chi-square bound of its 6 degrees of freedom)."""

_GTSAM_AXES = (3, 4, 5, 0, 1, 2)  # gtsam's Pose3 tangent is (rx, ry, rz, x, y, z); ours x first
_PRIOR_SIGMA = 1e-6  # the gauge: the reference's first vertex stays where it is
_WEAK = 1e-6  # of the strongest axis: information for an axis a measurement says nothing about


class RegistrationError(MapError):
    """The optimisation failed (gtsam's message says why)."""


def require_gtsam() -> Any:
    """The gtsam module.

    Raises:
        UsageError: it is not installed (the message says how to install it).
    """
    try:
        import gtsam
    except ImportError:
        raise UsageError(f"registration needs gtsam; install it with `{INSTALL_HINT}`") from None
    return gtsam


@dataclass(frozen=True)
class Residual:
    """The RMS residual of some edges: translation in metres, rotation in degrees."""

    metres: float
    degrees: float


@dataclass(frozen=True)
class Registration:
    """Where incoming missions lie in a reference mission's frame.

    Attributes:
        reference: the reference mission.
        frames: incoming mission -> its frame in the reference's (the pose of
            its origin), in the order given.
        edges: the inter-mission edges among the missions.
        inliers: those GNC kept.
        before: residual of the kept edges at the starting alignment.
        after: residual of the kept edges after the optimisation.
    """

    reference: str
    frames: dict[str, Pose]
    edges: int
    inliers: int
    before: Residual
    after: Residual


def linked_missions(
    graph: MissionGraph, among: Collection[str] | None = None, min_edges: int = MIN_EDGES
) -> list[str]:
    """The other missions `graph`'s own inter-mission edges reach with at least
    `min_edges` edges (of `among`, if given), sorted: what a robot knows is near
    it before fetching anything."""
    counts: dict[str, int] = {}
    for edge in graph.edges:
        for end in (edge.source, edge.target):
            if end[0] != graph.name and (among is None or end[0] in among):
                counts[end[0]] = counts.get(end[0], 0) + 1
    return sorted(name for name, n in counts.items() if n >= min_edges)


def register_missions(
    reference: MissionGraph, incoming: Sequence[MissionGraph], *, min_edges: int = MIN_EDGES
) -> Registration:
    """Register `incoming` missions in `reference`'s frame (module docstring).

    The result depends only on the graphs' content, not on the order of their
    edges, so equal missions give an equal answer wherever they are registered.

    Raises:
        UsageError: gtsam is missing; no incoming mission; two missions share a
            name; an edge names a vertex its mission lacks; an incoming mission
            shares fewer than `min_edges` edges with the reference; or an
            information matrix is not positive definite.
        RegistrationError: gtsam failed to optimise.
    """
    gtsam = require_gtsam()
    graphs = [reference, *incoming]
    _check_names(graphs)
    edges = _edges_among(graphs)
    position = {g.name: m for m, g in enumerate(graphs)}
    starts = {reference.name: np.eye(4)}
    for graph in incoming:
        links = [_link(e, reference, graph) for e in edges if _joins(e, reference, graph)]
        if len(links) < min_edges:
            raise UsageError(
                f"mission {graph.name!r} shares {len(links)} edges with {reference.name!r}; "
                f"registering it needs at least {min_edges}"
            )
        starts[graph.name] = consensus_frame(links)[0]
    initial = {
        _key(position, (g.name, i)): starts[g.name] @ pose_matrix(p)
        for g in graphs
        for i, p in g.vertices.items()
    }
    factors, values, known = gtsam.NonlinearFactorGraph(), gtsam.Values(), []
    for key, matrix in initial.items():
        values.insert(key, gtsam.Pose3(matrix))
    first = _key(position, (reference.name, min(reference.vertices)))
    known.append(factors.size())
    sigma = gtsam.noiseModel.Isotropic.Sigma(6, _PRIOR_SIGMA)
    factors.add(gtsam.PriorFactorPose3(first, gtsam.Pose3(initial[first]), sigma))
    inter = []
    for edge in edges:
        if edge.kind is EdgeKind.ODOMETRY:
            known.append(factors.size())
        elif edge.source[0] != edge.target[0]:
            inter.append((factors.size(), edge))
        factors.add(
            gtsam.BetweenFactorPose3(
                _key(position, edge.source),
                _key(position, edge.target),
                gtsam.Pose3(pose_matrix(edge.relative)),
                _noise(gtsam, edge),
            )
        )
    params = gtsam.GncLMParams()
    params.setKnownInliers(known)
    params.setLossType(gtsam.GncLossType.TLS)
    try:
        optimizer = gtsam.GncLMOptimizer(factors, values, params)
        optimizer.setInlierCostThresholdsAtProbability(INLIER_PROBABILITY)
        result = optimizer.optimize()
        weights = optimizer.getWeights()
    except RuntimeError as exc:
        raise RegistrationError(f"gtsam could not optimise the missions: {exc}") from None
    final = {key: result.atPose3(key).matrix() for key in initial}
    kept = [edge for index, edge in inter if weights[index] > 0.5]
    frames = {}
    for graph in incoming:
        first_index = min(graph.vertices)
        stored = pose_matrix(graph.vertices[first_index])
        frames[graph.name] = matrix_pose(
            final[_key(position, (graph.name, first_index))] @ invert(stored)
        )
    return Registration(
        reference.name,
        frames,
        len(inter),
        len(kept),
        _residual(kept, initial, position),
        _residual(kept, final, position),
    )


def _check_names(graphs: Sequence[MissionGraph]) -> None:
    if len(graphs) < 2:
        raise UsageError("no mission to register against the reference")
    names = [g.name for g in graphs]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise UsageError(f"missions named twice: {', '.join(twice)}")
    empty = [g.name for g in graphs if not g.vertices]
    if empty:
        raise UsageError(f"missions without vertices cannot be registered: {', '.join(empty)}")


def _edges_among(graphs: Sequence[MissionGraph]) -> list[GraphEdge]:
    """Every edge whose two ends lie in these missions, in a canonical order."""
    vertices = {g.name: g.vertices for g in graphs}
    edges = []
    for graph in graphs:
        for edge in graph.edges:
            if edge.source[0] not in vertices or edge.target[0] not in vertices:
                continue  # an edge to a mission outside this registration
            if edge.kind is EdgeKind.LANDMARK:
                continue  # frames come from pose-to-pose edges; its end is no pose
            for mission, index in (edge.source, edge.target):
                if index not in vertices[mission]:
                    raise UsageError(
                        f"mission {graph.name!r} has an edge to vertex {index} of "
                        f"{mission!r}, which has no such vertex"
                    )
            edges.append(edge)
    return sorted(edges, key=lambda e: (e.kind.value, e.source, e.target, e.relative))


def _key(position: dict[str, int], vertex: VertexKey) -> int:
    return (position[vertex[0]] << 32) | vertex[1]


def _joins(edge: GraphEdge, a: MissionGraph, b: MissionGraph) -> bool:
    return {edge.source[0], edge.target[0]} == {a.name, b.name}


def _link(edge: GraphEdge, reference: MissionGraph, graph: MissionGraph) -> Link:
    """An edge between `reference` and `graph`, seen from the reference's end."""
    measured = pose_matrix(edge.relative)
    if edge.source[0] == reference.name:
        return Link(reference.vertices[edge.source[1]], graph.vertices[edge.target[1]], measured)
    return Link(
        reference.vertices[edge.target[1]], graph.vertices[edge.source[1]], invert(measured)
    )


def _noise(gtsam: Any, edge: GraphEdge) -> Any:
    """The edge's Gaussian noise model, from its 6x6 information in gtsam's axis order."""
    info = np.zeros((6, 6))
    for i in range(6):
        for j in range(i, 6):
            info[i, j] = info[j, i] = edge.information[upper_index(i, j)]
    strongest = max(float(np.max(np.diag(info))), 0.0)
    for axis in range(6):
        if info[axis, axis] == 0.0 and strongest > 0:
            # a lifted 2D measurement says nothing about z, roll and pitch
            info[axis, axis] = _WEAK * strongest
    if strongest <= 0 or np.min(np.linalg.eigvalsh(info)) <= 0:
        raise UsageError(
            f"edge {edge.source} -> {edge.target}: its information matrix is not positive definite"
        )
    return gtsam.noiseModel.Gaussian.Information(info[np.ix_(_GTSAM_AXES, _GTSAM_AXES)])


def _residual(
    edges: Sequence[GraphEdge], poses: dict[int, np.ndarray], position: dict[str, int]
) -> Residual:
    """RMS residual ``Z⁻¹ · Ps⁻¹ · Pt`` of `edges` at `poses` (0 without edges)."""
    if not edges:
        return Residual(0.0, 0.0)
    errors = np.stack(
        [
            invert(pose_matrix(e.relative))
            @ invert(poses[_key(position, e.source)])
            @ poses[_key(position, e.target)]
            for e in edges
        ]
    )
    metres, radians = residuals(errors)
    return Residual(
        math.sqrt(float(np.mean(metres**2))), math.degrees(math.sqrt(float(np.mean(radians**2))))
    )
