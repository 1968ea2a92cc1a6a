"""A metric, Z-up world from an arbitrary SfM frame: the ground plane under the camera path.

One fit serves every importer, so the same cameras and points give the same plane whatever frame
or order they come in. It is deterministic (no random sampling) and every threshold is relative
to the cameras' height above the road, so it is unchanged by a similarity of its input.

Why this model. A car's cameras ride at a near-constant height over the road, and the road is
what lies right under their path; the rest of a street (kerbs and sidewalks a few centimetres
up, parked cars, facades) lies beside it. So:

1. **Corridor.** Only points under the path count: below it, and horizontally no farther from
   the camera path (a polyline per camera) than ``corridor`` times their depth below it. That
   cone keeps the road ahead and drops car bodies, facades and most of the kerb, in any units.
2. **Start.** The densest depth in the corridor (a 1 % histogram of log depth) is the road; the
   first plane goes through the points at that depth.
3. **Robust least squares (IRLS, Tukey's biweight).** The plane minimises the points' weighted
   squared heights plus ``path_weight`` times the cameras' squared height deviations from their
   mean, per camera: the camera path constrains the normal along the drive (and across it, on a
   curved drive) where a street's few road points would let it tip. Weights are redone each
   round from the median absolute residual of the last round's inliers, so a kerb 15 cm up, a
   dip, or a lane full of vehicles (more points under the path than the road has) does not pull.
   A given ``up`` fixes the normal; only the plane's height is fitted.

The fit records its quality (points in the corridor, inliers, residual RMS, the spread of the
cameras' heights) and says when it is weak. :func:`alignment` maps the source frame to the
package's world: the plane becomes ``z = 0`` with +Z up, the first camera stands over the origin
looking along +X (yaw and ground position are not observable), and the scale comes from the
cameras' height above that plane (``camera_height``) or is given. :func:`align` (fit, then
align) is what the importers call.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import SymDriveError
from .similarity import make_similarity

UP_HELP = ("pass --up x,y,z (the world's up direction in the source frame) and --camera-height H "
           "(the ground H metres below the cameras; --scale S too when the poses are not metric)")


class AlignmentError(SymDriveError):
    """No usable ground plane (or cameras below it): one line saying what to pass instead."""


@dataclass(frozen=True)
class GroundConfig:
    corridor: float = 1.0  # a point is under the path within this times its depth below it, horizontally
    path_weight: float = 1.0  # the cameras' constant-height term against the points' (both mean squares)
    max_tilt_deg: float = 30.0  # the plane's normal within this of the cameras' mean up vector
    tukey_c: float = 4.685  # biweight cut-off in robust standard deviations (95 % efficiency)
    min_sigma: float = 1e-3  # floor of the residuals' robust scale, in camera heights
    iterations: int = 50
    max_segments: int = 256  # per camera path (longer paths are thinned evenly)
    # A fit is weak below these (reported in the manifest and as a warning line).
    weak_inliers: int = 50
    weak_inlier_fraction: float = 0.3
    weak_residual_rms: float = 0.02  # in camera heights
    weak_height_spread: float = 0.03  # the cameras' height standard deviation, in camera heights
    weak_height_mismatch: float = 0.05  # a placed ground (--camera-height with --scale) this far from the fitted


DEFAULT = GroundConfig()


@dataclass
class Ground:
    normal: np.ndarray  # unit, pointing up (towards the cameras), source frame
    offset: float  # plane: normal . x + offset = 0
    inliers: int
    camera_heights: np.ndarray  # source units, per camera, above the plane
    corridor_points: int = 0  # points under the path the plane was fitted to
    residual_rms: float = 0.0  # of the inliers, source units

    def height(self, points) -> np.ndarray:
        return np.asarray(points, dtype=np.float64) @ self.normal + self.offset

    def quality(self, scale: float, cfg: GroundConfig = DEFAULT) -> dict:
        """The fit's numbers in metres (``scale``: metres per source unit) and why it is weak, if it is."""
        h = float(np.median(self.camera_heights))
        spread = float(np.std(self.camera_heights))
        q = {"corridor_points": self.corridor_points, "inliers": self.inliers,
             "inlier_fraction": round(self.inliers / max(self.corridor_points, 1), 4),
             "residual_rms_m": self.residual_rms * scale, "camera_height_spread_m": spread * scale}
        weak = []
        if self.corridor_points:
            if self.inliers < cfg.weak_inliers:
                weak.append(f"only {self.inliers} points on the plane")
            if q["inlier_fraction"] < cfg.weak_inlier_fraction:
                weak.append(f"{q['inlier_fraction']:.0%} of the points under the path on it")
            if self.residual_rms > cfg.weak_residual_rms * h:
                weak.append(f"residual RMS {self.residual_rms / h:.1%} of the camera height")
        if spread > cfg.weak_height_spread * h:
            weak.append(f"camera heights spread {spread / h:.1%} (a sloped or uneven road?)")
        q["weak"] = weak
        return q


def camera_up_vectors(c2ws: np.ndarray) -> np.ndarray:
    """World up of OpenCV cameras (their -y axis), [N, 3]."""
    return -np.asarray(c2ws)[..., :3, 1].reshape(-1, 3)


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    n = np.linalg.norm(v)
    if not np.isfinite(n) or n < 1e-12:
        raise AlignmentError(f"up vector {v.tolist()} has no direction; " + UP_HELP)
    return v / n


def camera_paths(c2ws) -> np.ndarray:
    """Camera centres as paths [C, F, 3]: ``c2ws`` is one camera's [F, 4, 4] or a rig's [C, F, 4, 4]."""
    c2ws = np.asarray(c2ws, dtype=np.float64)
    return c2ws[..., :3, 3].reshape(-1, c2ws.shape[-3], 3)


def path_scatter(paths: np.ndarray) -> np.ndarray:
    """Mean squared deviation of each camera's centres from their mean, averaged over cameras (3x3)."""
    rel = paths - paths.mean(axis=1, keepdims=True)
    return np.einsum("cfi,cfj->ij", rel, rel) / (paths.shape[0] * paths.shape[1])


def path_up(c2ws, turn_ratio: float = 0.05) -> np.ndarray:
    """The road's up direction from the camera path alone, for a drive with no points to fit.

    A camera's own up vector is tilted by its pitch (a degree of pitch puts the ground 0.9 m off
    over 50 m of drive), but the path is level along the drive: where the path turns enough to
    span a plane (its second extent at least ``turn_ratio`` of its first), that plane's normal;
    on a straight path, the cameras' mean up with its component along the drive removed. Its
    sign follows the cameras' up."""
    hint = _unit(camera_up_vectors(c2ws).mean(axis=0))
    extent, axes = np.linalg.eigh(path_scatter(camera_paths(c2ws)))  # ascending
    if extent[1] >= turn_ratio ** 2 * extent[2]:
        n = axes[:, 0]
    else:
        travel = axes[:, 2]
        n = hint - (hint @ travel) * travel
    n = _unit(n)
    return n if n @ hint > 0 else -n


def under_path(points: np.ndarray, paths: np.ndarray, up: np.ndarray, max_segments: int,
               chunk: int = 1024) -> tuple[np.ndarray, np.ndarray]:
    """Per point: horizontal distance to the nearest camera path segment, and depth below it there."""
    starts, ends = [], []
    for c in paths:
        if len(c) > max_segments + 1:
            c = c[np.linspace(0, len(c) - 1, max_segments + 1).round().astype(int)]
        starts.append(c[:-1] if len(c) > 1 else c)
        ends.append(c[1:] if len(c) > 1 else c)
    a, b = np.concatenate(starts), np.concatenate(ends)
    ab = b - a
    ab_h = ab - np.outer(ab @ up, up)
    len2 = np.maximum(np.einsum("ij,ij->i", ab_h, ab_h), 1e-300)
    r = np.empty(len(points))
    depth = np.empty(len(points))
    for s in range(0, len(points), chunk):
        rel = points[s:s + chunk, None, :] - a[None]  # [n, S, 3]
        rel_h = rel - (rel @ up)[..., None] * up
        t = np.clip(np.einsum("nsi,si->ns", rel_h, ab_h) / len2, 0.0, 1.0)
        off = rel_h - t[..., None] * ab_h
        dist = np.linalg.norm(off, axis=-1)
        j = np.argmin(dist, axis=1)
        idx = np.arange(len(j))
        r[s:s + chunk] = dist[idx, j]
        depth[s:s + chunk] = t[idx, j] * (ab[j] @ up) - rel[idx, j] @ up
    return r, depth


def _road_depth(depth: np.ndarray) -> float:
    """The densest depth (1 % bins of log depth, smoothed over five bins): the road under the path."""
    logd = np.log(depth)
    lo, hi = logd.min(), logd.max()
    bins = max(int(np.ceil((hi - lo) / 0.01)), 1)
    counts, edges = np.histogram(logd, bins=bins, range=(lo, lo + bins * 0.01))
    smooth = np.convolve(counts, np.ones(5), mode="same")
    k = int(np.argmax(smooth))
    return float(np.exp(0.5 * (edges[k] + edges[k + 1])))


def _plane(P: np.ndarray, w: np.ndarray, normal: np.ndarray | None, path_cov: np.ndarray, up0: np.ndarray,
           cfg: GroundConfig) -> tuple[np.ndarray, float]:
    """Weighted least-squares plane through ``P`` with the camera path's constant-height term
    (``normal`` given: only the offset is fitted)."""
    mu = (w @ P) / w.sum()
    if normal is None:
        rel = P - mu
        cov = (w[:, None] * rel).T @ rel / w.sum() + cfg.path_weight * path_cov
        normal = np.linalg.eigh(cov)[1][:, 0]
        normal = normal if normal @ up0 >= 0 else -normal
    return normal, -float(normal @ mu)


def _irls(P: np.ndarray, n: np.ndarray, d: float, scale_ref: float, path_cov: np.ndarray, up0: np.ndarray,
          fixed_normal: bool, cfg: GroundConfig) -> tuple[np.ndarray, float, np.ndarray]:
    """Tukey-weighted plane (see the module docstring); returns the normal, offset and inlier mask.
    The robust scale is the median absolute residual of the last round's inliers (first: the points
    within 2 % of the camera height of the starting plane), so it holds when most points under the
    path are not road."""
    inl = np.abs(P @ n + d) < 0.02 * scale_ref
    for _ in range(cfg.iterations):
        e = P @ n + d
        sigma = max(1.4826 * float(np.median(np.abs(e[inl]))) if inl.any() else 0.0, cfg.min_sigma * scale_ref)
        c = cfg.tukey_c * sigma
        inl = np.abs(e) < c
        w = np.where(inl, (1.0 - (e / c) ** 2) ** 2, 0.0)
        if w.sum() <= 0:
            break
        n_new, d_new = _plane(P, w, n if fixed_normal else None, path_cov, up0, cfg)
        done = np.linalg.norm(n_new - n) < 1e-12 and abs(d_new - d) < 1e-12 * scale_ref
        n, d = n_new, d_new
        if done:
            break
    return n, d, inl


def fit_ground(points, c2ws, *, up=None, cfg: GroundConfig = DEFAULT) -> Ground:
    """The ground plane under the cameras (see the module docstring); :class:`AlignmentError` if
    there is none. ``c2ws``: [F, 4, 4] or a rig's [C, F, 4, 4]; ``up``: the source frame's up
    direction, when known (fixes the normal)."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    points = points[np.isfinite(points).all(1)]
    paths = camera_paths(c2ws)
    centers = paths.reshape(-1, 3)
    up0 = _unit(up) if up is not None else _unit(camera_up_vectors(c2ws).mean(0))
    if len(points) < 3:
        raise AlignmentError(f"no ground plane: {len(points)} points to fit it to; " + UP_HELP)
    n, d, L = up0, 0.0, 0.0
    path_cov = path_scatter(paths)
    for _ in range(2):  # the corridor again under the fitted plane's up
        r, depth = under_path(points, paths, n, cfg.max_segments)
        cand = (depth > 0) & (r <= cfg.corridor * depth)
        if cand.sum() < 3:
            raise AlignmentError(f"no ground plane: {int(cand.sum())} points under the camera path; " + UP_HELP)
        P = points[cand]
        if L == 0.0:  # start: the plane through the points at the road's depth below the path
            L = _road_depth(depth[cand])
            band = (np.abs(np.log(depth[cand] / L)) < 0.02).astype(np.float64)
            n, d = _plane(P, band, up0 if up is not None else None, path_cov, up0, cfg)
        n, d, inl = _irls(P, n, d, L, path_cov, up0, up is not None, cfg)
        L = float(np.median(centers @ n + d))
        if not L > 0:
            break
    if np.degrees(np.arccos(np.clip(n @ up0, -1.0, 1.0))) > cfg.max_tilt_deg:
        raise AlignmentError(f"no ground plane within {cfg.max_tilt_deg:g} degrees of the cameras' up vector; "
                             + UP_HELP)
    heights = centers @ n + d
    if np.any(heights <= 0):
        raise AlignmentError(f"{int((heights <= 0).sum())} of {len(heights)} cameras are below the fitted "
                             "ground plane; " + UP_HELP)
    e = P[inl] @ n + d
    return Ground(n, d, int(inl.sum()), heights, corridor_points=len(P),
                  residual_rms=float(np.sqrt(np.mean(e ** 2))) if len(e) else 0.0)


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
              up=None, cfg: GroundConfig = DEFAULT) -> tuple[np.ndarray, dict]:
    """The similarity (4x4) from the source frame to the package world, and a record of how it
    was found (``ground_fit``: the fit's quality; empty ``weak`` when it is sound).

    The scale is ``scale`` (metres per source unit) when given, else ``camera_height`` (metres)
    over the fitted plane's median camera height, else 1 (poses taken as metric). With a known
    scale, ``camera_height`` places the plane: the ground is that far below the cameras' median
    height (its normal still fitted, or ``up``); without points that needs ``up``."""
    c2ws = np.asarray(c2ws, dtype=np.float64)
    centers = camera_paths(c2ws).reshape(-1, 3)
    fitted_height = None
    if ground is None:
        if up is None or camera_height is None:
            raise AlignmentError("no points to fit the ground plane to; " + UP_HELP)
        n = _unit(up)
        ground = Ground(n, 0.0, 0, centers @ n)
    else:
        fitted_height = float(np.median(ground.camera_heights))
    if scale is None and camera_height is not None and fitted_height:
        scale = float(camera_height) / fitted_height
    else:
        scale = 1.0 if scale is None else float(scale)
        if camera_height is not None:  # the ground camera_height below the cameras' median height
            shift = float(camera_height) / scale - float(np.median(ground.camera_heights))
            ground = Ground(ground.normal, ground.offset + shift, ground.inliers, ground.camera_heights + shift,
                            ground.corridor_points, ground.residual_rms)
    if not np.isfinite(scale) or scale <= 0:
        raise AlignmentError(f"scale {scale} is not a positive number")
    h_src = float(np.median(ground.camera_heights))
    R = rotation_to_z(ground.normal, c2ws.reshape(-1, 4, 4)[0][:3, 2])
    c0 = centers[0]
    foot = c0 - (c0 @ ground.normal + ground.offset) * ground.normal
    T = make_similarity(scale, R, -scale * R @ foot)
    record = {"ground_normal": ground.normal.tolist(), "ground_offset": float(ground.offset),
              "camera_height_source_units": h_src, "scale": float(scale), "camera_height_m": h_src * float(scale),
              "ground_fit": ground.quality(float(scale), cfg)}
    if fitted_height is not None:
        q = record["ground_fit"]
        q["fitted_camera_height_m"] = fitted_height * float(scale)
        if abs(fitted_height / h_src - 1) > cfg.weak_height_mismatch:
            q["weak"].append(f"the ground was placed {h_src * scale:.3f} m below the cameras, the fitted plane is "
                             f"{q['fitted_camera_height_m']:.3f} m below them: check --scale")
    return T, record


def align(points, c2ws, *, camera_height: float | None = None, scale: float | None = None, up=None,
          cfg: GroundConfig = DEFAULT) -> tuple[np.ndarray, dict]:
    """The importers' one entry: fit the ground to ``points`` (None: no points) and align (see
    :func:`alignment`). With ``up``, ``camera_height`` and ``scale`` all given the ground is placed
    whatever the points say, so a fit that fails (a poses-only drive's few triangulated road
    points) is reported, not fatal."""
    ground, failure = None, None
    if points is not None and len(points):
        try:
            ground = fit_ground(points, c2ws, up=up, cfg=cfg)
        except AlignmentError as exc:
            if up is None or camera_height is None or scale is None:
                raise
            failure = str(exc).split(";")[0]
    T, record = alignment(ground, c2ws, camera_height=camera_height, scale=scale, up=up, cfg=cfg)
    if failure:
        record["ground_fit"]["weak"].append(f"{failure} (the ground was placed by --up, --camera-height and --scale)")
    return T, record
