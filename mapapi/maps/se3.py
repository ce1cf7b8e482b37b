"""Pure SE(3) helpers for the importers: poses as 7-tuples, information matrices
as upper triangles. No numpy: the parsers stay light and exact."""

from __future__ import annotations

import math

# (x, y, z, qx, qy, qz, qw): translation in metres, unit quaternion, w last (g2o order).
Pose = tuple[float, float, float, float, float, float, float]

IDENTITY: Pose = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)

# Rows/columns of the 6x6 information (x, y, z, rx, ry, rz) that an SE(2)
# measurement (x, y, theta) occupies: theta is a rotation about z.
_SE2_AXES = (0, 1, 5)
# ... and that a 2D point observation (x, y) of a landmark occupies.
XY_AXES = (0, 1)


def upper_index(row: int, col: int, size: int = 6) -> int:
    """Position of (row, col), row <= col, in a row-major upper triangle."""
    return row * size - row * (row - 1) // 2 + (col - row)


def lift_information(
    upper: tuple[float, ...], axes: tuple[int, ...] = _SE2_AXES
) -> tuple[float, ...]:
    """The 21-value 6x6 upper triangle of a smaller information's upper
    triangle over `axes`: by default a 3x3 SE(2) one (6 values), whose entries
    land on (x, y, rz); `XY_AXES` for a 2D point's 2x2 (3 values). Other axes
    get zero information: a planar graph says nothing about them.
    """
    out = [0.0] * 21
    k = 0
    for i in range(len(axes)):
        for j in range(i, len(axes)):
            out[upper_index(axes[i], axes[j])] = upper[k]
            k += 1
    return tuple(out)


def project_information(
    upper6: tuple[float, ...], axes: tuple[int, ...] = _SE2_AXES
) -> tuple[float, ...]:
    """Inverse of `lift_information`: the block over `axes`, as an upper triangle."""
    return tuple(
        upper6[upper_index(axes[i], axes[j])] for i in range(len(axes)) for j in range(i, len(axes))
    )


def invert_upper(upper: tuple[float, ...], source: str = "", line: int = 0) -> tuple[float, ...]:
    """The inverse of a symmetric 2x2 or 3x3 matrix given as its upper triangle
    (3 or 6 values), as its upper triangle: a covariance's information.

    Raises:
        ValueError: the matrix is not positive definite.
    """
    if len(upper) == 3:
        a, b, d = upper
        det = a * d - b * b
        if not (a > 0 and det > 0):
            raise ValueError(f"covariance {upper} is not positive definite")
        return (d / det, -b / det, a / det)
    a, b, c, d, e, f = upper
    # cofactors of [[a b c] [b d e] [c e f]]
    m00, m01, m02 = d * f - e * e, c * e - b * f, b * e - c * d
    det = a * m00 + b * m01 + c * m02
    if not (a > 0 and a * d - b * b > 0 and det > 0):
        raise ValueError(f"covariance {upper} is not positive definite")
    m11, m12, m22 = a * f - c * c, b * c - a * e, a * d - b * b
    return tuple(v / det for v in (m00, m01, m02, m11, m12, m22))


def isotropic_information(tau: float, kappa: float) -> tuple[float, ...]:
    """The 6x6 information of an SE-Sync/DPGO measurement with translation
    precision `tau` and rotation precision `kappa`: diag(tau I3, 2 kappa I3)
    (SE-Sync reads g2o as tau = 3/tr(Σt), kappa = 3/(2 tr(ΣR)))."""
    out = [0.0] * 21
    for axis in range(6):
        out[upper_index(axis, axis)] = tau if axis < 3 else 2.0 * kappa
    return tuple(out)


def from_se2(x: float, y: float, theta: float) -> Pose:
    """A planar pose lifted to SE(3): yaw becomes a rotation about z."""
    half = 0.5 * theta
    return (x, y, 0.0, 0.0, 0.0, math.sin(half), math.cos(half))


def yaw(pose: Pose) -> float:
    """The rotation about z of a planar pose (inverse of `from_se2`)."""
    return 2.0 * math.atan2(pose[5], pose[6])


def is_planar(pose: Pose, tol: float = 1e-12) -> bool:
    """True when the pose lies in z = 0 and rotates about z only."""
    return abs(pose[2]) <= tol and abs(pose[3]) <= tol and abs(pose[4]) <= tol


def compose(a: Pose, b: Pose) -> Pose:
    """a ∘ b: b expressed in a's frame, then mapped to a's parent frame."""
    ax, ay, az, qx, qy, qz, qw = a
    bx, by, bz, rx, ry, rz, rw = b
    # t = a.t + R(a.q) b.t, via t' = v + 2 q_v x (q_v x v + w v)
    cx = qy * bz - qz * by + qw * bx
    cy = qz * bx - qx * bz + qw * by
    cz = qx * by - qy * bx + qw * bz
    tx = ax + bx + 2.0 * (qy * cz - qz * cy)
    ty = ay + by + 2.0 * (qz * cx - qx * cz)
    tz = az + bz + 2.0 * (qx * cy - qy * cx)
    ox = qw * rx + qx * rw + qy * rz - qz * ry
    oy = qw * ry - qx * rz + qy * rw + qz * rx
    oz = qw * rz + qx * ry - qy * rx + qz * rw
    ow = qw * rw - qx * rx - qy * ry - qz * rz
    norm = math.sqrt(ox * ox + oy * oy + oz * oz + ow * ow)
    return (tx, ty, tz, ox / norm, oy / norm, oz / norm, ow / norm)


def inverse(pose: Pose) -> Pose:
    """The inverse of a pose: the parent frame's origin seen from the pose's frame,
    so that `compose(inverse(a), b)` is `b` relative to `a`."""
    x, y, z, qx, qy, qz, qw = pose
    # rotate -t by the conjugate quaternion (the same formula as `compose`)
    cx = qy * z - qz * y - qw * x
    cy = qz * x - qx * z - qw * y
    cz = qx * y - qy * x - qw * z
    tx = -x + 2.0 * (-qy * cz + qz * cy)
    ty = -y + 2.0 * (-qz * cx + qx * cz)
    tz = -z + 2.0 * (-qx * cy + qy * cx)
    return (tx, ty, tz, -qx, -qy, -qz, qw)
