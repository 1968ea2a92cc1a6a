"""Colour surface points from the images that see them (depth-tested projection).

A point takes the colour of the pixel it lands on in the first camera whose depth map agrees
with the point's depth; points no camera sees are reported as unseen (a real capture has no
colour for them either).
"""

from __future__ import annotations

import numpy as np

from .. import conventions


def colour_points(points, views, rel_tol: float = 0.02, abs_tol: float = 0.05):
    """``views``: iterable of (K, world_to_camera, image [H,W,3], depth [H,W] with 0 = none).

    Returns (colours [N,3] float32, seen [N] bool, nearest depth at which it was seen [N]).
    Among the views that see a point, the one seeing it from closest wins (sharpest colour).
    """
    points = np.asarray(points, dtype=np.float64)
    n = len(points)
    colours = np.zeros((n, 3), np.float32)
    best = np.full(n, np.inf)
    for K, w2c, image, depth in views:
        h, w = depth.shape
        uv, z = conventions.project_points(points, w2c, K)
        with np.errstate(invalid="ignore"):
            u = np.floor(uv[:, 0]).astype(np.int64, copy=False)
            v = np.floor(uv[:, 1]).astype(np.int64, copy=False)
        ok = (z > 0) & (u >= 0) & (u < w) & (v >= 0) & (v < h) & (z < best)
        idx = np.nonzero(ok)[0]
        d = depth[v[idx], u[idx]]
        agree = (d > 0) & (np.abs(d - z[idx]) <= abs_tol + rel_tol * z[idx])
        idx = idx[agree]
        colours[idx] = image[v[idx], u[idx], :3]
        best[idx] = z[idx]
    return colours, np.isfinite(best), best
