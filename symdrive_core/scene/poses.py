"""Rigid poses: quaternions (w, x, y, z), rotation matrices, and trajectory interpolation.

numpy only. Interpolation is linear in translation and spherical (slerp) in rotation, the
convention of tracklet-driven actors in street reconstructions.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def quat_normalize(q) -> np.ndarray:
    q = np.asarray(q, dtype=np.float64)
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.any(n == 0):
        raise ValueError("zero quaternion has no rotation")
    return q / n


def quat_multiply(a, b) -> np.ndarray:
    """Hamilton product a ⊗ b (rotate by b, then by a)."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack([
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ], axis=-1)


def quat_to_matrix(q) -> np.ndarray:
    """Unit-normalised wxyz quaternion(s) [..., 4] -> rotation matrix [..., 3, 3]."""
    w, x, y, z = np.moveaxis(quat_normalize(q), -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], axis=-2)


def matrix_to_quat(R) -> np.ndarray:
    """Rotation matrix [3, 3] -> unit wxyz quaternion with w >= 0 (Shepperd's method)."""
    R = np.asarray(R, dtype=np.float64)
    tr = np.trace(R)
    if tr > 0:
        s = 2.0 * np.sqrt(tr + 1.0)
        q = [0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s]
    else:
        i = int(np.argmax(np.diag(R)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(max(1.0 + R[i, i] - R[j, j] - R[k, k], 0.0))
        q = [0.0, 0.0, 0.0, 0.0]
        q[0] = (R[k, j] - R[j, k]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (R[j, i] + R[i, j]) / s
        q[1 + k] = (R[k, i] + R[i, k]) / s
    q = np.asarray(q)
    q = q / np.linalg.norm(q)
    return -q if q[0] < 0 else q


def quat_from_yaw(yaw_rad: float) -> np.ndarray:
    """Rotation about world Z (heading), as used for ground vehicles."""
    return np.array([np.cos(yaw_rad / 2.0), 0.0, 0.0, np.sin(yaw_rad / 2.0)])


def quat_slerp(q0, q1, u: float) -> np.ndarray:
    """Shortest-arc spherical interpolation, u in [0, 1]."""
    q0, q1 = quat_normalize(q0), quat_normalize(q1)
    dot = float(np.dot(q0, q1))
    if dot < 0.0:
        q1, dot = -q1, -dot
    if dot > 0.9995:  # nearly parallel: lerp is exact to float precision and avoids 0/0
        return quat_normalize(q0 + u * (q1 - q0))
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    s = np.sin(theta)
    return (np.sin((1 - u) * theta) * q0 + np.sin(u * theta) * q1) / s


@dataclass(frozen=True)
class Pose:
    """Maps a local frame to the world: x_w = R x_l + T."""

    translation: np.ndarray  # [3]
    rotation: np.ndarray  # [4] wxyz, unit

    @staticmethod
    def from_matrix(M) -> Pose:
        M = np.asarray(M, dtype=np.float64)
        return Pose(M[:3, 3].copy(), matrix_to_quat(M[:3, :3]))

    @staticmethod
    def identity() -> Pose:
        return Pose(np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0]))

    @property
    def R(self) -> np.ndarray:
        return quat_to_matrix(self.rotation)

    def matrix(self) -> np.ndarray:
        M = np.eye(4)
        M[:3, :3] = self.R
        M[:3, 3] = self.translation
        return M

    def apply(self, points) -> np.ndarray:
        return np.asarray(points, dtype=np.float64) @ self.R.T + self.translation

    def compose(self, other: Pose) -> Pose:
        """self ∘ other: first ``other``, then ``self``."""
        return Pose(self.apply(other.translation[None])[0],
                    quat_normalize(quat_multiply(self.rotation, other.rotation)))

    def to_json(self) -> dict:
        return {"translation": [float(v) for v in self.translation],
                "rotation": [float(v) for v in self.rotation]}


def interpolate_pose(times, poses: list[Pose], t: float) -> Pose:
    """Pose at time ``t`` from keyed ``poses`` at increasing ``times`` (clamped at the ends)."""
    times = np.asarray(times, dtype=np.float64)
    if len(poses) != len(times) or len(poses) == 0:
        raise ValueError("interpolate_pose needs as many poses as times, at least one")
    if np.any(np.diff(times) <= 0):
        raise ValueError("interpolate_pose: times must increase strictly")
    if t <= times[0]:
        return poses[0]
    if t >= times[-1]:
        return poses[-1]
    i = int(np.searchsorted(times, t, side="right")) - 1
    u = (t - times[i]) / (times[i + 1] - times[i])
    a, b = poses[i], poses[i + 1]
    return Pose((1 - u) * a.translation + u * b.translation, quat_slerp(a.rotation, b.rotation, u))


def yaw_of(rotation) -> float:
    """Heading angle about world Z of a rotation's forward (+X) axis."""
    fwd = quat_to_matrix(rotation)[:, 0]
    return float(np.arctan2(fwd[1], fwd[0]))
