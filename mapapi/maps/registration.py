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
from mapapi.maps.alignment import (
    Link,
    consensus_frame,
    invert,
    matrix_pose,
    pose_matrix,
    residuals,
    rigid_fit,
)
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
_OUR_AXES = _GTSAM_AXES  # the same swap takes gtsam's order back to ours
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
    graphs = [reference, *incoming]
    _check_names(graphs)
    edges = edges_among(graphs)
    starts = {reference.name: np.eye(4)}
    for graph in incoming:
        links = links_between(edges, reference, graph)
        if len(links) < min_edges:
            raise UsageError(
                f"mission {graph.name!r} shares {len(links)} edges with {reference.name!r}; "
                f"registering it needs at least {min_edges}"
            )
        starts[graph.name] = consensus_frame(links)[0]
    solved = optimise_missions(graphs, starts)
    frames = {g.name: solved.frames[g.name] for g in incoming}
    return Registration(
        reference.name, frames, solved.edges, solved.inliers, solved.before, solved.after
    )


@dataclass(frozen=True)
class Optimised:
    """What `optimise_missions` found.

    Attributes:
        frames: mission -> its frame in the first mission's (the pose of its origin).
        fitted: mission -> the rigid motion that best takes its stored positions
            onto its optimised ones (least squares over every vertex): where its
            stored trajectory lies best, drift and all, in the first mission's frame.
        covariances: mission -> the 6x6 covariance of its frame (x, y, z, rx, ry,
            rz), from the marginals of the graph of the edges GNC kept; empty
            unless asked for.
        edges, inliers, before, after: as in `Registration`.
        kept: mission pair (sorted) -> the inter-mission edges GNC kept between them.
    """

    frames: dict[str, Pose]
    fitted: dict[str, Pose]
    covariances: dict[str, np.ndarray]
    edges: int
    inliers: int
    before: Residual
    after: Residual
    kept: dict[tuple[str, str], int]


def optimise_missions(
    graphs: Sequence[MissionGraph], starts: dict[str, np.ndarray], *, covariance: bool = False
) -> Optimised:
    """Optimise missions' poses together, each starting in the frame `starts` gives
    it, with the first mission's first vertex held fixed (the gauge): steps 2 and 3
    of the module docstring. With `covariance`, also each frame's covariance.

    Raises:
        UsageError: gtsam is missing; an edge names a vertex its mission lacks; an
            information matrix is not positive definite.
        RegistrationError: gtsam failed to optimise.
    """
    gtsam = require_gtsam()
    edges = edges_among(graphs)
    position = {g.name: m for m, g in enumerate(graphs)}
    initial = {
        _key(position, (g.name, i)): starts[g.name] @ pose_matrix(p)
        for g in graphs
        for i, p in g.vertices.items()
    }
    factors, values, known = gtsam.NonlinearFactorGraph(), gtsam.Values(), []
    for key, matrix in initial.items():
        values.insert(key, gtsam.Pose3(matrix))
    first = _key(position, (graphs[0].name, min(graphs[0].vertices)))
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
    firsts = {g.name: _key(position, (g.name, min(g.vertices))) for g in graphs}
    frames, fitted = {}, {}
    for graph in graphs:
        stored = pose_matrix(graph.vertices[min(graph.vertices)])
        frames[graph.name] = matrix_pose(final[firsts[graph.name]] @ invert(stored))
        keys = [_key(position, (graph.name, i)) for i in graph.vertices]
        before = np.array([p[:3] for p in graph.vertices.values()])
        after = np.array([final[k][:3, 3] for k in keys])
        fitted[graph.name] = matrix_pose(rigid_fit(before, after))
    covariances = {}
    if covariance:
        outliers = {index for index, _ in inter if weights[index] <= 0.5}
        trusted = gtsam.NonlinearFactorGraph()
        for index in range(factors.size()):
            if index not in outliers:
                trusted.add(factors.at(index))
        try:
            marginals = gtsam.Marginals(trusted, result)
            covariances = {
                name: marginals.marginalCovariance(key)[np.ix_(_OUR_AXES, _OUR_AXES)]
                for name, key in firsts.items()
            }
        except RuntimeError as exc:
            raise RegistrationError(f"gtsam could not find the frames' covariance: {exc}") from None
    pairs: dict[tuple[str, str], int] = {}
    for edge in kept:
        a, b = edge.source[0], edge.target[0]
        pairs[(min(a, b), max(a, b))] = pairs.get((min(a, b), max(a, b)), 0) + 1
    return Optimised(
        frames,
        fitted,
        covariances,
        len(inter),
        len(kept),
        _residual(kept, initial, position),
        _residual(kept, final, position),
        pairs,
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


def edges_among(graphs: Sequence[MissionGraph]) -> list[GraphEdge]:
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


def links_between(
    edges: Sequence[GraphEdge], reference: MissionGraph, graph: MissionGraph
) -> list[Link]:
    """The edges between `reference` and `graph`, each seen from the reference's end."""
    pair = {reference.name, graph.name}
    return [_link(e, reference, graph) for e in edges if {e.source[0], e.target[0]} == pair]


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
