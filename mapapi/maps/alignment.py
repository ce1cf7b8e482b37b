"""Rigid alignment of one mission's frame to another's from the edges between
them, with numpy: the starting point of a registration (`mapapi.maps.registration`).

Poses are 4x4 homogeneous matrices here. Every inter-mission edge, taken alone,
says where the other mission's frame lies: if vertex ``g`` of the reference
and vertex ``a`` of the incoming mission are joined by a measurement ``Z``
(``g⁻¹ · T · a ≈ Z``), the incoming frame is ``T = g · Z · a⁻¹``. Outliers
(wrong place recognitions) say something else, so each edge's candidate is
scored by how many edges it explains within `METRES` and `DEGREES`, measured
where each edge is (so a small rotation error far from the frames' origins is
not magnified), and the best-supported candidate wins (a consensus, as in
RANSAC, but trying every candidate: a mission pair has a few hundred edges).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from mapapi.maps.se3 import Pose

METRES = 2.0
DEGREES = 10.0
"""The consensus tolerance: an edge supports a candidate frame when, in that
frame, the edge's residual is within these (odometry drift over a tunnel's
length makes edges far apart disagree by metres)."""


def pose_matrix(pose: Pose) -> np.ndarray:
    """The 4x4 matrix of a pose 7-tuple (x, y, z, qx, qy, qz, qw)."""
    x, y, z, qx, qy, qz, qw = pose
    n = math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
    qx, qy, qz, qw = qx / n, qy / n, qz / n, qw / n
    return np.array(
        [
            [1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * qw), 2 * (qx * qz + qy * qw), x],
            [2 * (qx * qy + qz * qw), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qx * qw), y],
            [2 * (qx * qz - qy * qw), 2 * (qy * qz + qx * qw), 1 - 2 * (qx * qx + qy * qy), z],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def matrix_pose(matrix: np.ndarray) -> Pose:
    """The pose 7-tuple of a 4x4 rigid matrix (its quaternion with w >= 0)."""
    r = matrix[:3, :3]
    trace = r[0, 0] + r[1, 1] + r[2, 2]
    # Shepperd: divide by the largest of the four candidates, never by a small one
    if trace > max(r[0, 0], r[1, 1], r[2, 2]):
        s = 2.0 * math.sqrt(1.0 + trace)
        q = ((r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s, s / 4)
    elif r[0, 0] >= r[1, 1] and r[0, 0] >= r[2, 2]:
        s = 2.0 * math.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2])
        q = (s / 4, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s, (r[2, 1] - r[1, 2]) / s)
    elif r[1, 1] >= r[2, 2]:
        s = 2.0 * math.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2])
        q = ((r[0, 1] + r[1, 0]) / s, s / 4, (r[1, 2] + r[2, 1]) / s, (r[0, 2] - r[2, 0]) / s)
    else:
        s = 2.0 * math.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1])
        q = ((r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, s / 4, (r[1, 0] - r[0, 1]) / s)
    sign = -1.0 if q[3] < 0 else 1.0
    norm = sign / math.sqrt(sum(v * v for v in q))
    x, y, z = (float(v) for v in matrix[:3, 3])
    return (x, y, z, q[0] * norm, q[1] * norm, q[2] * norm, q[3] * norm)


def invert(matrix: np.ndarray) -> np.ndarray:
    """The inverse of rigid 4x4 matrices (one, or a stack of them)."""
    out = np.zeros_like(matrix)
    rt = np.swapaxes(matrix[..., :3, :3], -1, -2)
    out[..., :3, :3] = rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", rt, matrix[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


def residuals(error: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The translation (metres) and rotation angle (radians) of error transforms
    (a stack of 4x4 matrices, identity when a measurement is met exactly)."""
    translation = np.linalg.norm(error[..., :3, 3], axis=-1)
    r = error[..., :3, :3]
    cosine = (np.trace(r, axis1=-2, axis2=-1) - 1.0) / 2.0
    axis = np.stack(
        [r[..., 2, 1] - r[..., 1, 2], r[..., 0, 2] - r[..., 2, 0], r[..., 1, 0] - r[..., 0, 1]]
    )
    # atan2, not arccos: arccos loses precision near 0, where a residual usually is
    return translation, np.arctan2(np.linalg.norm(axis, axis=0) / 2.0, cosine)


def rigid_fit(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The rigid motion (4x4) that best takes points `source` onto `target` (both
    n x 3) in least squares: Kabsch's method, with no reflection."""
    mean_s, mean_t = source.mean(axis=0), target.mean(axis=0)
    u, _, vt = np.linalg.svd((source - mean_s).T @ (target - mean_t))
    sign = np.sign(np.linalg.det(vt.T @ u.T)) or 1.0
    rotation = vt.T @ np.diag([1.0, 1.0, sign]) @ u.T
    motion = np.eye(4)
    motion[:3, :3] = rotation
    motion[:3, 3] = mean_t - rotation @ mean_s
    return motion


@dataclass(frozen=True)
class Link:
    """An inter-mission edge seen from the reference: ``g⁻¹ · T · a ≈ measured``.

    Attributes:
        reference: the reference vertex's pose, in the reference frame.
        incoming: the incoming vertex's pose, in the incoming mission's own frame.
        measured: the incoming vertex as seen from the reference vertex.
    """

    reference: Pose
    incoming: Pose
    measured: np.ndarray


def candidates(links: Sequence[Link]) -> np.ndarray:
    """Each link's frame of the incoming mission, ``g · Z · a⁻¹`` (n x 4 x 4)."""
    g = np.stack([pose_matrix(link.reference) for link in links])
    a = np.stack([pose_matrix(link.incoming) for link in links])
    z = np.stack([link.measured for link in links])
    return g @ z @ invert(a)


def support(
    links: Sequence[Link], frames: np.ndarray, metres: float = METRES, degrees: float = DEGREES
) -> np.ndarray:
    """For each of `frames` (k x 4 x 4), how many links it explains within the
    tolerance: the residual ``Z⁻¹ · g⁻¹ · T · a`` of each link, at the link."""
    g = np.stack([pose_matrix(link.reference) for link in links])
    a = np.stack([pose_matrix(link.incoming) for link in links])
    z = np.stack([link.measured for link in links])
    left = invert(z) @ invert(g)  # n x 4 x 4
    error = np.einsum("nab,kbc,ncd->knad", left, frames, a)
    translation, angle = residuals(error)
    return np.count_nonzero((translation <= metres) & (angle <= math.radians(degrees)), axis=1)


def consensus_frame(links: Sequence[Link]) -> tuple[np.ndarray, int]:
    """The incoming frame most links agree on, and how many do (ties: the
    earliest link's candidate, so equal input gives an equal answer).

    Raises:
        ValueError: no links.
    """
    if not links:
        raise ValueError("no inter-mission edges to align with")
    frames = candidates(links)
    votes = support(links, frames)
    best = int(np.argmax(votes))
    return frames[best], int(votes[best])
