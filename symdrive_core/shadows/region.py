"""The shadow region of an inserted vehicle: where harmonization may darken the ground.

The vehicle's box is projected onto the ground plane along the sun direction (the direction
light travels); the convex hull of the footprint and the projected corners is the largest
shadow the car can cast. Each pixel's viewing ray is intersected with the ground plane and
tested against that hull (exact, and correct for rays that never reach the ground), then the
region is dilated a few pixels for soft edges. No sun (or a sun at or below the horizon) -> no
shadow region. numpy only.
"""

from __future__ import annotations

import numpy as np

from .. import conventions
from ..conventions import sun_above_horizon
from ..scene import Pose
from ..splat.constants import ALPHA_THRESHOLD


def convex_hull(points: np.ndarray) -> np.ndarray:
    """Counter-clockwise convex hull [M, 2] of 2D points (Andrew's monotone chain)."""
    pts = sorted({(float(x), float(y)) for x, y in np.asarray(points, dtype=np.float64)})
    if len(pts) < 3:
        return np.asarray(pts, dtype=np.float64)

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower, upper = [], []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return np.asarray(lower[:-1] + upper[:-1], dtype=np.float64)


def vehicle_ground_z(pose: Pose, wlh) -> float:
    """Height of the ground a vehicle stands on: the bottom of its box at ``pose``."""
    return float(pose.apply(conventions.vehicle_box_corners(wlh))[:, 2].min())


def shadow_polygon(pose: Pose, wlh, sun_direction, ground_z: float | None = None) -> np.ndarray | None:
    """Ground-plane hull [M, 2] (world x, y) of the box's shadow, None when the sun is down."""
    s = sun_above_horizon(sun_direction)
    if s is None:
        return None
    corners = pose.apply(conventions.vehicle_box_corners(wlh))
    gz = vehicle_ground_z(pose, wlh) if ground_z is None else float(ground_z)
    t = (gz - corners[:, 2]) / s[2]
    on_ground = corners + np.clip(t, 0.0, None)[:, None] * s
    return convex_hull(np.concatenate([corners[:, :2], on_ground[:, :2]]))


def ground_hits(c2w: np.ndarray, K: np.ndarray, width: int, height: int, ground_z: float):
    """World (x, y) [H, W, 2] where each pixel centre's ray meets z = ground_z, and a hit mask."""
    u, v = conventions.pixel_centers(width, height)
    K = np.asarray(K, dtype=np.float64)
    rays_cam = np.stack([(u - K[0, 2] - K[0, 1] * (v - K[1, 2]) / K[1, 1]) / K[0, 0],
                         (v - K[1, 2]) / K[1, 1], np.ones_like(u)], -1)
    c2w = np.asarray(c2w, dtype=np.float64)
    rays = rays_cam @ c2w[:3, :3].T
    origin = c2w[:3, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (ground_z - origin[2]) / rays[..., 2]
    hit = np.isfinite(t) & (t > 0)
    xy = origin[:2] + np.where(hit, t, 0.0)[..., None] * rays[..., :2]
    return xy, hit


def inside_convex(xy: np.ndarray, hull: np.ndarray) -> np.ndarray:
    """True where points [..., 2] lie inside a counter-clockwise convex polygon."""
    inside = np.ones(xy.shape[:-1], dtype=bool)
    for a, b in zip(hull, np.roll(hull, -1, axis=0)):
        inside &= (b[0] - a[0]) * (xy[..., 1] - a[1]) - (b[1] - a[1]) * (xy[..., 0] - a[0]) >= 0
    return inside


def dilate(mask: np.ndarray, radius: int) -> np.ndarray:
    """Binary dilation with a (2r+1)^2 square, as two separable running maxima."""
    out = np.asarray(mask, dtype=bool)
    r = int(radius)
    if r <= 0:
        return out.copy()
    for axis in (0, 1):
        padded = np.pad(out, [(r, r) if a == axis else (0, 0) for a in (0, 1)])
        n = out.shape[axis]
        acc = np.zeros_like(out)
        for k in range(2 * r + 1):
            acc |= np.take(padded, np.arange(k, k + n), axis=axis)
        out = acc
    return out


def shadow_region(pose: Pose, wlh, sun_direction, c2w: np.ndarray, K: np.ndarray, width: int, height: int,
                  *, ground_z: float | None = None, dilate_px: int = 3) -> np.ndarray | None:
    """Bool mask [H, W] of the pixels the vehicle's shadow may cover; None without a sun."""
    if sun_direction is None:
        return None
    hull = shadow_polygon(pose, wlh, sun_direction, ground_z)
    if hull is None or len(hull) < 3:
        return None
    gz = vehicle_ground_z(pose, wlh) if ground_z is None else ground_z
    xy, hit = ground_hits(c2w, K, width, height, gz)
    return dilate(hit & inside_convex(xy, hull), dilate_px)


def harmonization_region(vehicle_alpha: np.ndarray, shadow: np.ndarray | None, *, threshold: float = ALPHA_THRESHOLD,
                         dilate_px: int = 2) -> np.ndarray:
    """The pixels harmonization may change: the vehicle (dilated for its rim) ∪ its shadow region."""
    region = dilate(np.asarray(vehicle_alpha) > threshold, dilate_px)
    return region | shadow if shadow is not None else region
