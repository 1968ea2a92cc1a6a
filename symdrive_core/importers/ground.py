"""A metric, Z-up world from an arbitrary SfM frame: the ground plane under the camera path.

The ground is fitted by RANSAC on the reconstruction's points (sparse SfM points or splat
centres) near the camera path and below the cameras. A street has more than one plane (kerbs and
sidewalks a few centimetres higher, facades, car roofs), so a candidate plane must be within
``max_tilt_deg`` of the cameras' mean up vector, lie below every camera, and is scored by its
inliers weighted by closeness to the path rather than by its size alone. The result maps the
source frame to the package's world: the plane becomes ``z = 0`` with +Z up, the first camera
stands over the origin looking along +X (yaw and ground position are not observable), and the
scale comes from the cameras' height above that plane (``camera_height``) or is given.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import SymDriveError
from .similarity import make_similarity

UP_HELP = ("pass --up x,y,z (the world's up direction in the source frame) and --scale S "
           "(metres per source unit)")


class AlignmentError(SymDriveError):
    """No usable ground plane (or cameras below it): one line saying what to pass instead."""


@dataclass
class Ground:
    normal: np.ndarray  # unit, pointing up (towards the cameras), source frame
    offset: float  # plane: normal . x + offset = 0
    inliers: int
    camera_heights: np.ndarray  # source units, per camera, above the plane

    def height(self, points) -> np.ndarray:
        return np.asarray(points, dtype=np.float64) @ self.normal + self.offset


def camera_up_vectors(c2ws: np.ndarray) -> np.ndarray:
    """World up of OpenCV cameras (their -y axis), [N, 3]."""
    return -np.asarray(c2ws)[:, :3, 1]


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    n = np.linalg.norm(v)
    if not np.isfinite(n) or n < 1e-12:
        raise AlignmentError(f"up vector {v.tolist()} has no direction; " + UP_HELP)
    return v / n


def _near_path(points: np.ndarray, centers: np.ndarray, up: np.ndarray, max_points: int, rng) -> tuple:
    """Per point (subsampled): height below its horizontally nearest camera, horizontal distance."""
    if len(points) > max_points:
        points = points[rng.choice(len(points), max_points, replace=False)]
    if len(centers) > 200:
        centers = centers[np.linspace(0, len(centers) - 1, 200).round().astype(int)]
    best_r = np.full(len(points), np.inf)
    best_h = np.zeros(len(points))
    for s in range(0, len(points), 4096):
        p = points[s:s + 4096]
        rel = p[:, None, :] - centers[None]
        v = rel @ up
        r = np.linalg.norm(rel - v[..., None] * up, axis=-1)
        j = np.argmin(r, axis=1)
        idx = np.arange(len(p))
        best_r[s:s + 4096] = r[idx, j]
        best_h[s:s + 4096] = -v[idx, j]
    return points, best_h, best_r


def fit_ground(points, c2ws, *, up=None, max_tilt_deg: float = 30.0, iterations: int = 600,
               seed: int = 0, max_points: int = 60000) -> Ground:
    """The ground plane under the cameras (see the module docstring); :class:`AlignmentError` if
    there is none. ``up``: the source frame's up direction, when known (fixes the normal)."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    points = points[np.isfinite(points).all(1)]
    c2ws = np.asarray(c2ws, dtype=np.float64)
    centers = c2ws[:, :3, 3]
    rng = np.random.default_rng(seed)
    up0 = _unit(up) if up is not None else _unit(camera_up_vectors(c2ws).mean(0))
    if len(points) < 3:
        raise AlignmentError(f"no ground plane: {len(points)} points to fit it to; " + UP_HELP)
    pts, h, r = _near_path(points, centers, up0, max_points, rng)
    below = h > 0
    if below.sum() < 3:
        raise AlignmentError("no ground plane: no points below the cameras; " + UP_HELP)
    # Rough camera height: points below the cameras and horizontally near them.
    near = below & (r <= np.median(r[below]))
    L = float(np.median(h[near])) if near.any() else float(np.median(h[below]))
    cand = below & (r < 4.0 * L)
    if cand.sum() < 3:
        cand = below
    P, rP = pts[cand], r[cand]
    weight = np.exp(-(rP / (2.0 * L)) ** 2)
    tau = 0.02 * L
    cos_tilt = np.cos(np.deg2rad(max_tilt_deg))
    best = None
    for _ in range(iterations):
        if up is not None:
            n = up0
            d = -float(P[rng.integers(len(P))] @ n)
        else:
            a, b, c = P[rng.choice(len(P), 3, replace=False)]
            n = np.cross(b - a, c - a)
            norm = np.linalg.norm(n)
            if norm < 1e-12:
                continue
            n = n / norm
            if n @ up0 < 0:
                n = -n
            if n @ up0 < cos_tilt:
                continue
            d = -float(n @ a)
        if np.any(centers @ n + d <= 0):
            continue
        inl = np.abs(P @ n + d) < tau
        score = float(weight[inl].sum())
        if best is None or score > best[0]:
            best = (score, n, d)
    if best is None:
        raise AlignmentError(f"no ground plane within {max_tilt_deg:g} degrees of the cameras' up vector "
                             "with every camera above it; " + UP_HELP)
    _, n, d = best
    for _ in range(3):  # refine on the inliers by least squares (the normal kept when it is given)
        inl = np.abs(P @ n + d) < tau
        Q = P[inl]
        if len(Q) < 3:
            break
        c = Q.mean(0)
        if up is None:
            _, _, vt = np.linalg.svd(Q - c, full_matrices=False)
            n2 = vt[-1] if vt[-1] @ n > 0 else -vt[-1]
            if n2 @ up0 >= cos_tilt:
                n = n2
        d = -float(n @ c)
    heights = centers @ n + d
    if np.any(heights <= 0):
        raise AlignmentError(f"{int((heights <= 0).sum())} of {len(heights)} cameras are below the fitted "
                             "ground plane; " + UP_HELP)
    return Ground(n, d, int((np.abs(P @ n + d) < tau).sum()), heights)


def rotation_to_z(n: np.ndarray, forward: np.ndarray) -> np.ndarray:
    """The rotation taking unit ``n`` to +Z and the horizontal part of ``forward`` to +X."""
    n = _unit(n)
    f = np.asarray(forward, dtype=np.float64)
    f = f - (f @ n) * n
    if np.linalg.norm(f) < 1e-9:  # looking straight down or up: any horizontal axis
        f = np.cross(n, [1.0, 0.0, 0.0])
        if np.linalg.norm(f) < 1e-9:
            f = np.cross(n, [0.0, 1.0, 0.0])
    x = _unit(f)
    y = np.cross(n, x)
    return np.stack([x, y, n])  # rows: source directions of the new X, Y, Z


def alignment(ground: Ground | None, c2ws, *, camera_height: float | None = None, scale: float | None = None,
              up=None) -> tuple[np.ndarray, dict]:
    """The similarity (4x4) from the source frame to the package world, and a record of how it
    was found. Either ``camera_height`` (metres: the cameras' median height above the ground)
    or ``scale`` (metres per source unit) sets the scale; neither: 1."""
    c2ws = np.asarray(c2ws, dtype=np.float64)
    centers = c2ws[:, :3, 3]
    if ground is None:
        if up is None:
            raise AlignmentError("no ground plane and no up direction; " + UP_HELP)
        n = _unit(up)
        if scale is None:
            raise AlignmentError("without a ground plane the scale cannot come from --camera-height; " + UP_HELP)
        # Without points: the ground lies camera_height (metres) below the lowest camera.
        below = (camera_height or 0.0) / scale
        d = -float((centers @ n).min()) + below
        heights = centers @ n + d
        ground = Ground(n, d, 0, heights)
    h_src = float(np.median(ground.camera_heights))
    if scale is None:
        scale = 1.0 if camera_height is None else float(camera_height) / h_src
    if not np.isfinite(scale) or scale <= 0:
        raise AlignmentError(f"scale {scale} is not a positive number")
    R = rotation_to_z(ground.normal, c2ws[0][:3, 2])
    foot = centers[0] - (centers[0] @ ground.normal + ground.offset) * ground.normal
    T = make_similarity(scale, R, -scale * R @ foot)
    record = {"ground_normal": ground.normal.tolist(), "ground_offset": float(ground.offset),
              "ground_inliers": ground.inliers, "camera_height_source_units": h_src,
              "scale": float(scale), "camera_height_m": h_src * float(scale)}
    return T, record
