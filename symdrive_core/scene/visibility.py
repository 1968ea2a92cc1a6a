"""Which actors can appear in which frames: conservative frustum tests on bounding boxes.

numpy only. A box is culled only when all 8 of its corners lie outside one frustum plane
(near, left, right, top, bottom), so a visible actor is never dropped; a box that straddles a
corner of the frustum may be kept although it is not visible (harmless: it renders empty).
"""

from __future__ import annotations

import numpy as np

from .. import conventions


def box_corners_world(local_min, local_max, rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
    """8 corners [8, 3] of a local axis-aligned box moved by x_w = R x_l + T."""
    lo, hi = np.asarray(local_min, dtype=np.float64), np.asarray(local_max, dtype=np.float64)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    return corners @ np.asarray(rotation, dtype=np.float64).T + np.asarray(translation, dtype=np.float64)


def box_in_frustum(corners_world: np.ndarray, w2c: np.ndarray, K: np.ndarray, width: int, height: int,
                   near: float = conventions.NEAR_PLANE, far: float = conventions.FAR_PLANE) -> bool:
    """False only if the box is certainly outside the camera's view."""
    w2c = np.asarray(w2c, dtype=np.float64)
    p = np.asarray(corners_world, dtype=np.float64) @ w2c[:3, :3].T + w2c[:3, 3]
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    # Each row: corner is inside this half-space (image bounds written without dividing by z).
    inside = [
        z >= near,
        z <= far,
        fx * x + cx * z >= 0.0,
        fx * x + (cx - width) * z <= 0.0,
        fy * y + cy * z >= 0.0,
        fy * y + (cy - height) * z <= 0.0,
    ]
    return not any(not np.any(half) for half in inside)


def vehicle_local_box(wlh) -> tuple[np.ndarray, np.ndarray]:
    corners = conventions.vehicle_box_corners(wlh)
    return corners.min(0), corners.max(0)
