"""Put an asset's Gaussians into the world at a pose, standing on the ground.

mu_w = R mu_l + T and q_w = q_R ⊗ q_l (scales unchanged). SH coefficients are NOT rotated: the
renderer evaluates a vehicle's SH with the view direction taken into the vehicle frame, so
:func:`place` output is meant for degree-0 use (previews, exports) or paired with its pose.
"""

from __future__ import annotations

import numpy as np

from .. import conventions
from ..gaussians import Gaussians
from ..rotations import quat_multiply
from .poses import Pose


def place(g: Gaussians, pose: Pose) -> Gaussians:
    """World-frame copy of vehicle-frame Gaussians."""
    R = pose.R
    means = g.means.astype(np.float64) @ R.T + pose.translation
    quats = quat_multiply(np.asarray(pose.rotation, dtype=np.float64)[None], g.quats.astype(np.float64))
    normals = None if g.normals is None else (g.normals.astype(np.float64) @ R.T).astype(np.float32)
    return Gaussians(means.astype(np.float32), quats.astype(np.float32), g.log_scales.copy(),
                     g.opacity_logits.copy(), g.sh.copy(), normals, dict(g.extra))


def ground_height(points_world: np.ndarray, pose: Pose, wlh, *, margin: float = 0.5,
                  percentile: float = 20.0) -> float | None:
    """Height of the ground under a vehicle's footprint, from scene points (None if none there).

    Points inside the footprint (grown by ``margin``) and below the car's roof are kept; a low
    percentile of their heights ignores the odd point of a kerb or of something overhead.
    """
    p = np.asarray(points_world, dtype=np.float64)
    local = (p - pose.translation) @ pose.R
    w, length, h = (float(v) for v in wlh)
    inside = ((np.abs(local[:, 0]) <= length / 2 + margin) & (np.abs(local[:, 1]) <= w / 2 + margin)
              & (local[:, 2] <= h / 2))
    if not inside.any():
        return None
    return float(np.percentile(p[inside, 2], percentile))


def grounded(pose: Pose, wlh, ground_z: float) -> Pose:
    """The pose moved vertically so the car's underside rests at ``ground_z``."""
    t = np.array(pose.translation, dtype=np.float64)
    t[2] = ground_z + conventions.vehicle_ground_offset(wlh)
    return Pose(t, np.asarray(pose.rotation, dtype=np.float64))
