"""Rigid poses (translation + wxyz rotation) and trajectory interpolation.

numpy only. Interpolation is linear in translation and spherical (slerp) in rotation, the
convention of tracklet-driven actors in street reconstructions.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..rotations import matrix_to_quat, quat_multiply, quat_normalize, quat_slerp, quat_to_matrix


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

    def close_to(self, other: Pose, tolerance_m: float = 1e-3) -> bool:
        """Within ``tolerance_m`` in position and in the motion of a point 1 m from the origin."""
        turn = np.linalg.norm(self.R - other.R, 2)
        return bool(np.linalg.norm(self.translation - other.translation) <= tolerance_m and turn <= tolerance_m)

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


def travels(poses: list[Pose | None], metres: float) -> bool:
    """Whether the centres of ``poses`` (None: not seen) span more than ``metres``: a vehicle that
    drives, not one parked whose boxes only jitter."""
    centres = np.array([p.translation for p in poses if p is not None])
    return len(centres) > 1 and float(np.linalg.norm(centres.max(0) - centres.min(0))) > metres
