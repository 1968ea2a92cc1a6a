"""Float64 brute-force oracle, written independently of the fast path (numpy only).

Per Gaussian: its own projection (same published numerics); per pixel: every Gaussian in global
depth order, no tiles, no early loop exit. The rules are the rasterizer's: alpha clamp 0.99, skip
``alpha < threshold`` and ``sigma < 0``, and a pixel whose transmittance would fall to 1e-4 or
below ignores that Gaussian and all behind it. A Gaussian touches only the pixels of the 16x16 tiles
its box overlaps (in "opacity" extent mode this never changes the result: outside the box alpha is
below the threshold anyway; ``tile_cull=False`` drops the rule).
"""

from __future__ import annotations

import math

import numpy as np

from ..conventions import FAR_PLANE, NEAR_PLANE
from .constants import ALPHA_MAX, ALPHA_THRESHOLD, EPS2D, EXTENT_CAP, FOV_CLAMP_MARGIN, T_STOP

C0 = 0.28209479177387814
C1 = 0.4886025119029199
C2 = [1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792, 0.5462742152960396]
C3 = [-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154, -0.4570457994644658,
      1.445305721320277, -0.5900435899266435]


def _sh_color(deg, sh, d):
    n = np.linalg.norm(d, axis=1, keepdims=True)
    d = np.where(n > 0, d / np.where(n > 0, n, 1.0), 0.0)
    x, y, z = d[:, 0:1], d[:, 1:2], d[:, 2:3]
    r = C0 * sh[:, 0]
    if deg > 0:
        r = r - C1 * y * sh[:, 1] + C1 * z * sh[:, 2] - C1 * x * sh[:, 3]
    if deg > 1:
        xx, yy, zz, xy, yz, xz = x * x, y * y, z * z, x * y, y * z, x * z
        r = (r + C2[0] * xy * sh[:, 4] + C2[1] * yz * sh[:, 5] + C2[2] * (2 * zz - xx - yy) * sh[:, 6]
             + C2[3] * xz * sh[:, 7] + C2[4] * (xx - yy) * sh[:, 8])
    if deg > 2:
        r = (r + C3[0] * y * (3 * xx - yy) * sh[:, 9] + C3[1] * xy * z * sh[:, 10]
             + C3[2] * y * (4 * zz - xx - yy) * sh[:, 11] + C3[3] * z * (2 * zz - 3 * xx - 3 * yy) * sh[:, 12]
             + C3[4] * x * (4 * zz - xx - yy) * sh[:, 13] + C3[5] * z * (xx - yy) * sh[:, 14]
             + C3[6] * x * (xx - 3 * yy) * sh[:, 15])
    return np.maximum(r + 0.5, 0.0)


def _rotmat(q):
    n = np.linalg.norm(q)
    w, x, y, z = (q / n) if n > 1e-15 and np.all(np.isfinite(q)) else (1.0, 0.0, 0.0, 0.0)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def render_oracle(means, quats, scales, opacities, colors, viewmat, K, width, height, *, background=None,
                  sh_degree=None, near=NEAR_PLANE, far=FAR_PLANE, eps2d=EPS2D, antialiased=False, render_depth=False,
                  alpha_threshold=ALPHA_THRESHOLD, extent="opacity", tile_cull=True, tile_size=16):
    """Returns dict(rgb [H,W,C], alpha [H,W,1], depth [H,W,1] or None, radii [N,2]) in float64."""
    f = lambda a: np.asarray(a.detach().cpu().numpy() if hasattr(a, "detach") else a, dtype=np.float64)
    means, quats, scales, opac, colors = f(means), f(quats), f(scales), f(opacities), f(colors)
    V, K = f(viewmat), f(K)
    n = means.shape[0]
    R, t = V[:3, :3], V[:3, 3]
    cam = -R.T @ t
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    tanx, tany = 0.5 * width / fx, 0.5 * height / fy
    if colors.ndim == 3:
        deg = int(round(math.sqrt(colors.shape[1]))) - 1 if sh_degree is None else sh_degree
        cols = _sh_color(deg, colors, means - cam)
    else:
        cols = colors
    C = cols.shape[1]
    recs = []
    radii = np.zeros((n, 2), np.int64)
    for i in range(n):
        if not (np.all(np.isfinite(means[i])) and np.all(np.isfinite(scales[i])) and np.isfinite(opac[i])
                and np.all(np.isfinite(quats[i])) and np.all(np.isfinite(cols[i]))):
            continue
        p = R @ (means[i] - cam)
        x, y, z = p
        if z < near or z > far:
            continue
        txz = min(max(x / z, -(cx / fx + FOV_CLAMP_MARGIN * tanx)), (width - cx) / fx + FOV_CLAMP_MARGIN * tanx)
        tyz = min(max(y / z, -(cy / fy + FOV_CLAMP_MARGIN * tany)), (height - cy) / fy + FOV_CLAMP_MARGIN * tany)
        J = np.array([[fx / z, 0.0, -fx * txz / z], [0.0, fy / z, -fy * tyz / z]])
        M = _rotmat(quats[i]) @ np.diag(scales[i])
        cov = J @ R @ M @ M.T @ R.T @ J.T
        det0 = cov[0, 0] * cov[1, 1] - cov[0, 1] ** 2
        cb = cov + eps2d * np.eye(2)
        det = cb[0, 0] * cb[1, 1] - cb[0, 1] ** 2
        if det <= 0:
            continue
        o = opac[i]
        if antialiased:
            o = o * math.sqrt(max(0.005 ** 2, det0 / det))
        if o < alpha_threshold:
            continue
        if extent == "opacity":
            cap = EXTENT_CAP if alpha_threshold >= ALPHA_THRESHOLD else math.sqrt(2 * math.log(1 / alpha_threshold))
            k = min(cap, math.sqrt(2 * math.log(max(o / alpha_threshold, 1.0))))
        elif extent == "3sigma":
            k = 3.0
        else:
            k = float(extent)
        rx, ry = math.ceil(k * math.sqrt(cb[0, 0])), math.ceil(k * math.sqrt(cb[1, 1]))
        u, v = fx * x / z + cx, fy * y / z + cy
        if u + rx <= 0 or u - rx >= width or v + ry <= 0 or v - ry >= height or (rx <= 0 and ry <= 0):
            continue
        radii[i] = (rx, ry)
        conic = np.array([cb[1, 1], -cb[0, 1], cb[0, 0]]) / det
        recs.append((z, i, u, v, conic, o, rx, ry))
    recs.sort(key=lambda r: (r[0], r[1]))
    us, vs = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    tile_x, tile_y = np.floor(us / tile_size), np.floor(vs / tile_size)
    T = np.ones((height, width))
    out = np.zeros((height, width, C))
    depth = np.zeros((height, width))
    done = np.zeros((height, width), bool)
    for z, i, u, v, conic, o, rx, ry in recs:
        dx, dy = u - us, v - vs
        sigma = 0.5 * (conic[0] * dx * dx + conic[2] * dy * dy) + conic[1] * dx * dy
        alpha = np.minimum(ALPHA_MAX, o * np.exp(-np.maximum(sigma, 0.0)))
        use = (sigma >= 0) & (alpha >= alpha_threshold) & ~done
        if tile_cull:
            ntx, nty = math.ceil(width / tile_size), math.ceil(height / tile_size)
            x0 = min(max(0, math.floor((u - rx) / tile_size)), ntx)
            x1 = min(max(0, math.ceil((u + rx) / tile_size)), ntx)
            y0 = min(max(0, math.floor((v - ry) / tile_size)), nty)
            y1 = min(max(0, math.ceil((v + ry) / tile_size)), nty)
            use &= (tile_x >= x0) & (tile_x < x1) & (tile_y >= y0) & (tile_y < y1)
        nextT = T * (1 - alpha)
        stop = use & (nextT <= T_STOP)
        done |= stop
        use &= ~stop
        w = np.where(use, alpha * T, 0.0)
        out += w[..., None] * cols[i]
        depth += w * z
        T = np.where(use, nextT, T)
    alpha_img = 1.0 - T
    rgb = out
    if background is not None:
        rgb = rgb + (1.0 - alpha_img[..., None]) * f(background)
    d = None
    if render_depth:
        d = np.where(alpha_img > 0, depth / np.where(alpha_img > 0, alpha_img, 1.0), 0.0)[..., None]
    return {"rgb": rgb, "alpha": alpha_img[..., None], "depth": d, "radii": radii}
