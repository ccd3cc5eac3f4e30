"""Poses: 4x4 matrices at the API, unit quaternion + translation on the wire.

QUATERNION ORDER: the SGMQ protocol sends quaternions as **w x y z** (docs/protocol.md 1).
ROS (geometry_msgs/Quaternion, tf2, scipy's Rotation.as_quat) uses **x y z w**. Passing a ROS
quaternion unchanged silently gives a wrong rotation (or BAD_QUATERNION); convert it with
wxyz_from_ros_xyzw() first.

A pose T_a_b maps points of frame b into frame a: p_a = T_a_b @ [p_b, 1].
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence, Tuple

import numpy as np

QUATERNION_NORM_TOLERANCE = 1e-3  # docs/protocol.md 1: refused beyond, normalised within
# Tolerance of a rotation matrix's orthonormality at the API (a matrix chained from float32 or
# parsed from text is not exact; anything further off is a bug in the caller's pose).
ROTATION_TOLERANCE = 1e-6


def wxyz_from_ros_xyzw(q_xyzw: Sequence[float]) -> Tuple[float, float, float, float]:
    """A ROS quaternion (x y z w) in the protocol's order (w x y z)."""
    x, y, z, w = (float(v) for v in q_xyzw)
    return (w, x, y, z)


def ros_xyzw_from_wxyz(q_wxyz: Sequence[float]) -> Tuple[float, float, float, float]:
    """A protocol quaternion (w x y z) in ROS's order (x y z w)."""
    w, x, y, z = (float(v) for v in q_wxyz)
    return (x, y, z, w)


def check_quaternion(q_wxyz: Sequence[float], what: str = "quaternion") -> Tuple[float, ...]:
    """The quaternion as 4 floats (w x y z) if the server would accept it; ValueError otherwise."""
    q = tuple(float(v) for v in np.asarray(q_wxyz, dtype=float).reshape(-1))
    if len(q) != 4:
        raise ValueError(f"{what}: expected 4 values w x y z (ROS order x y z w must be reordered), got {len(q)}")
    if not all(math.isfinite(v) for v in q):
        raise ValueError(f"{what}: not finite: {q}")
    norm = math.sqrt(sum(v * v for v in q))
    if abs(norm - 1.0) > QUATERNION_NORM_TOLERANCE:
        raise ValueError(f"{what}: norm {norm:.6g} is not within {QUATERNION_NORM_TOLERANCE} of 1 (w x y z expected)")
    return q


def unit_quaternion(q_wxyz: Sequence[float]) -> Tuple[float, float, float, float]:
    """q / |q|, as the C++ encoder sends it. A quaternion already unit to double precision is
    returned unchanged: dividing by a norm of 1 +- 1 ulp only flips last bits, and keeping them
    makes a decoded frame re-encode to the same bytes."""
    w, x, y, z = (float(v) for v in q_wxyz)
    norm = math.sqrt(w * w + x * x + y * y + z * z)
    if not (math.isfinite(norm) and norm > 0.0):
        raise ValueError(f"quaternion {q_wxyz} cannot be normalised")
    if abs(norm - 1.0) <= 4e-16:
        return (w, x, y, z)
    return (w / norm, x / norm, y / norm, z / norm)


def rotation_from_quaternion(q_wxyz: Sequence[float]) -> np.ndarray:
    """3x3 rotation matrix of a (normalised here) quaternion w x y z; Eigen's formula."""
    w, x, y, z = unit_quaternion(q_wxyz)
    tx, ty, tz = 2 * x, 2 * y, 2 * z
    twx, twy, twz = tx * w, ty * w, tz * w
    txx, txy, txz = tx * x, ty * x, tz * x
    tyy, tyz, tzz = ty * y, tz * y, tz * z
    return np.array([
        [1 - (tyy + tzz), txy - twz, txz + twy],
        [txy + twz, 1 - (txx + tzz), tyz - twx],
        [txz - twy, tyz + twx, 1 - (txx + tyy)],
    ])


def check_rotation(R, what: str = "rotation") -> np.ndarray:
    """R as a float 3x3 array if it is a rotation (orthonormal, det +1); ValueError otherwise."""
    R = np.asarray(R, dtype=float)
    if R.shape != (3, 3):
        raise ValueError(f"{what}: expected a 3x3 matrix, got shape {R.shape}")
    if not np.all(np.isfinite(R)):
        raise ValueError(f"{what}: not finite")
    err = np.max(np.abs(R.T @ R - np.eye(3)))
    if err > ROTATION_TOLERANCE or np.linalg.det(R) <= 0:
        raise ValueError(f"{what}: not a rotation (orthonormality error {err:.3g}, det {np.linalg.det(R):.6g})")
    return R


def quaternion_from_rotation(R) -> Tuple[float, float, float, float]:
    """Unit quaternion w x y z of a rotation matrix (Eigen's branch structure, so a pose sent by
    this client and by the C++ client gives the same wire values up to rounding)."""
    m = check_rotation(R)
    t = m[0, 0] + m[1, 1] + m[2, 2]
    q = [0.0, 0.0, 0.0, 0.0]  # x y z w, Eigen's coefficient order
    if t > 0:
        t = math.sqrt(t + 1.0)
        q[3] = 0.5 * t
        t = 0.5 / t
        q[0] = (m[2, 1] - m[1, 2]) * t
        q[1] = (m[0, 2] - m[2, 0]) * t
        q[2] = (m[1, 0] - m[0, 1]) * t
    else:
        i = 0
        if m[1, 1] > m[0, 0]:
            i = 1
        if m[2, 2] > m[i, i]:
            i = 2
        j, k = (i + 1) % 3, (i + 2) % 3
        t = math.sqrt(m[i, i] - m[j, j] - m[k, k] + 1.0)
        q[i] = 0.5 * t
        t = 0.5 / t
        q[3] = (m[k, j] - m[j, k]) * t
        q[j] = (m[j, i] + m[i, j]) * t
        q[k] = (m[k, i] + m[i, k]) * t
    return unit_quaternion((float(q[3]), float(q[0]), float(q[1]), float(q[2])))


@dataclass(frozen=True)
class Pose:
    """A rigid transform exactly as on the wire: unit quaternion **w x y z** (not ROS's x y z w)
    and translation x y z. Decoded frames keep these values bit for bit, so they re-encode to the
    same bytes; use matrix() / from_matrix() at the API."""

    q_wxyz: Tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    t: Tuple[float, float, float] = (0.0, 0.0, 0.0)

    def matrix(self) -> np.ndarray:
        """The 4x4 homogeneous matrix (float64)."""
        T = np.eye(4)
        T[:3, :3] = rotation_from_quaternion(self.q_wxyz)
        T[:3, 3] = self.t
        return T

    @classmethod
    def from_matrix(cls, T, what: str = "pose") -> "Pose":
        """From a 4x4 homogeneous matrix; ValueError if it is not a finite rigid transform."""
        T = np.asarray(T, dtype=float)
        if T.shape != (4, 4):
            raise ValueError(f"{what}: expected a 4x4 matrix, got shape {T.shape}")
        if not np.all(np.isfinite(T)):
            raise ValueError(f"{what}: not finite")
        if np.max(np.abs(T[3] - [0, 0, 0, 1])) > 1e-12:
            raise ValueError(f"{what}: last row must be 0 0 0 1, got {T[3]}")
        q = quaternion_from_rotation(check_rotation(T[:3, :3], what + " rotation"))
        return cls(q, tuple(float(v) for v in T[:3, 3]))
