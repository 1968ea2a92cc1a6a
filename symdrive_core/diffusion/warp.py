"""Geometry-guided conditions: the neighbouring recorded frames warped into a lateral camera.

At a few metres sideways the reconstruction smears what the recorded drive saw sharply: the road
ahead, lane paint included, is in the neighbouring frames, seen at an angle. Each pixel of the
lateral camera (recorded frame ``t`` moved sideways) whose ray meets the ground below the horizon
and within ``max_range_m`` is back-projected onto a piecewise planar ground model; that point is
projected into every recorded frame ``s`` in ``t - radius .. t + radius`` (never ``t`` itself,
so a training target cannot see its own image in its own warp) and its colour sampled
bilinearly where all four source pixels show the ground there (their depth agrees with the
ground model's: an object in front, a kerb or the sky fails). The samples are fused with weights
falling with ``|s - t|``; pixels no frame sees take the raw render.

Depth of the ground from the model, not from the reconstruction's render: rendered road depth
wiggles, and the lane line with it. The source frames' depth is the package's recorded depth
(``cameras[].frames[].depth``, decoded by :mod:`..scene.depth`) at the pixels it measured, the
reconstruction's rendered depth with a looser tolerance at the pixels it did not (all of them
where a frame has no depth; most of them with sparse LiDAR depth); sky is never ground. The
ground model is one plane per window of frames along the camera path, each fitted by
:func:`~..importers.ground.fit_ground` to the package's points (``background.points``) or the
splat centres; a ray takes the plane of the window whose anchor camera is nearest to where it
meets the ground. Structure from motion finds few road points on a real street (grey asphalt,
the car's own hood at the bottom of the image), so a window whose points give no plane takes, in
this order, one fitted to the reconstruction's splat centres (which cover the road it renders), a
neighbouring window's, the package's own ground (an imported package's world has the ground its
import fitted at ``z = 0``), or the nearest fitted window's; :meth:`GroundModel.summary` says which
window took which, for the reports.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .. import conventions
from ..errors import SymDriveError
from ..importers.ground import AlignmentError, fit_ground
from ..scene.depth import UNMEASURED, measured, read_depth


class WarpError(SymDriveError):
    """The package lacks what the warp needs (points to fit the ground, depth for occlusion)."""


@dataclass(frozen=True)
class WarpConfig:
    radius: int = 8  # source frames t - radius .. t + radius, t excluded
    falloff_frames: float = 4.0  # source weight exp(-|s - t| / falloff_frames)
    max_range_m: float = 40.0  # ground pixels: z-depth at most this
    ground_window: int = 8  # each plane is fitted to the points near cameras anchor +- this many frames
    ground_stride: int = 4  # a plane anchored every this many frames
    # A window without a plane of its own borrows one from a window at most this many anchors away
    # before the package's ground plane (whose single plane ignores a slope's changes).
    neighbour_windows: int = 2
    # A source pixel shows the ground where its depth is within this fraction of the ground
    # model's (0.03: about 5 cm of height at a 1.6 m camera; a kerb or a car fails).
    depth_tolerance: float = 0.03
    rendered_depth_tolerance: float = 0.10  # the same with the reconstruction's depth (noisier)
    # A lateral pixel whose rendered depth is shorter than (1 - this) x the ground's has something
    # in front of the ground (a car, a pole): the warp leaves it to the render.
    occluder_margin: float = 0.25
    min_alpha: float = 0.5  # rendered depth counts where the render is this opaque


DEFAULT = WarpConfig()


# What a window's plane was fitted to, in the order they are tried (see the module docstring).
PLANE_SOURCES = ("points", "splats", "neighbour", "package", "nearest")
WORLD_GROUND = (np.array([0.0, 0.0, 1.0]), 0.0)  # an imported package's ground: z = 0, +Z up


@dataclass
class GroundModel:
    """Planes ``normal . x + offset = 0`` (normals up), each anchored at a camera centre."""

    anchors: np.ndarray  # [K, 3] anchor camera centres
    normals: np.ndarray  # [K, 3]
    offsets: np.ndarray  # [K]
    # Per plane: its cameras (first, last), what it was fitted to (PLANE_SOURCES) and, for a
    # borrowed plane, why the window's own points gave none.
    windows: list[tuple[int, int]] = field(default_factory=list)
    sources: list[str] = field(default_factory=list)
    reasons: list[str] = field(default_factory=list)

    @classmethod
    def fit(cls, points, c2ws, config: WarpConfig = DEFAULT, *, splats=None, package_ground=None) -> GroundModel:
        """A plane per window of ``2 * ground_window + 1`` cameras, one every ``ground_stride``.
        A window whose ``points`` give no plane tries ``splats`` (the reconstruction's centres),
        then a neighbouring window's plane, ``package_ground`` ((normal, offset) or None), then the
        nearest window's; a :class:`WarpError` only when nothing gives any plane."""
        c2ws = np.asarray(c2ws, dtype=np.float64)
        n = len(c2ws)
        anchors = list(range(0, n, max(1, config.ground_stride)))
        if anchors[-1] != n - 1:
            anchors.append(n - 1)
        windows = [(max(0, a - config.ground_window), min(n, a + config.ground_window + 1) - 1) for a in anchors]
        planes, sources, reasons = [], [], []
        for lo, hi in windows:
            plane, source, reason = _window_plane(c2ws[lo:hi + 1], (("points", points), ("splats", splats)))
            planes.append(plane)
            sources.append(source)
            reasons.append(reason)
        fitted = [k for k, p in enumerate(planes) if p is not None]
        if not fitted and package_ground is None:
            raise WarpError(f"the geometry-guided warp found no ground under cameras {windows[0][0]} to "
                            f"{windows[-1][1]}: {reasons[0]}")
        for k in range(len(planes)):
            if planes[k] is not None:
                continue
            near = min(fitted, key=lambda j: (abs(j - k), j), default=None)
            if near is not None and abs(near - k) <= config.neighbour_windows:
                planes[k], sources[k] = planes[near], "neighbour"
            elif package_ground is not None:
                planes[k], sources[k] = (np.asarray(package_ground[0], np.float64), float(package_ground[1])), "package"
            else:
                planes[k], sources[k] = planes[near], "nearest"
        return cls(c2ws[anchors, :3, 3], np.array([p[0] for p in planes]), np.array([p[1] for p in planes]),
                   windows, sources, reasons)

    def summary(self) -> dict:
        """How many planes each source gave and, for every plane not fitted to the window's own
        points, its cameras, source and why the points gave none (the reports' ``ground``)."""
        counts = {s: self.sources.count(s) for s in PLANE_SOURCES if s in self.sources}
        borrowed = [{"cameras": list(w), "plane": s, "why": r}
                    for w, s, r in zip(self.windows, self.sources, self.reasons) if s != "points"]
        return {"planes": counts, **({"other_than_points": borrowed} if borrowed else {})}

    def intersect(self, origin, dirs: np.ndarray, iterations: int = 3) -> tuple[np.ndarray, np.ndarray]:
        """Ray parameter ``lam`` (x = origin + lam * dir) where each ray meets the ground, and
        whether it does (in front of the origin, going down). The plane is the one anchored
        nearest to the previous hit, starting from the one nearest the origin."""
        origin = np.asarray(origin, dtype=np.float64)
        k = np.full(len(dirs), int(np.argmin(np.linalg.norm(self.anchors - origin, axis=1))))
        for _ in range(iterations):
            nrm, off = self.normals[k], self.offsets[k]
            denom = np.einsum("ij,ij->i", dirs, nrm)
            hits = denom < -1e-12
            lam = np.where(hits, -(nrm @ origin + off) / np.where(hits, denom, -1.0), 0.0)
            if len(self.anchors) == 1:
                break
            x = origin + lam[:, None] * dirs
            d2 = ((x[:, None, :] - self.anchors[None]) ** 2).sum(-1)
            k = np.where(hits, np.argmin(d2, axis=1), k)
        return lam, hits & (lam > 0)


def _window_plane(c2ws, clouds) -> tuple[tuple[np.ndarray, float] | None, str, str]:
    """The first of ``clouds`` ((name, points or None), ...) that gives a ground plane under
    ``c2ws``: ((normal, offset), its name, why the ones before it gave none), else (None, "", why)."""
    why = ""
    for name, cloud in clouds:
        if cloud is None:
            continue
        try:
            g = fit_ground(cloud, c2ws)
        except AlignmentError as e:
            why = why or str(e).split(";")[0]
            continue
        return (g.normal, g.offset), name, why
    return None, "", why


def pixel_rays(K, c2w, width: int, height: int) -> np.ndarray:
    """World directions [H*W, 3] through every pixel centre, scaled so camera z = 1 (the ray
    parameter is then the z-depth)."""
    xs, ys = np.meshgrid(np.arange(width), np.arange(height))
    cam = conventions.pixel_rays_camera(K, xs.ravel(), ys.ravel())
    return cam @ np.asarray(c2w, dtype=np.float64)[:3, :3].T


@dataclass
class SourceFrame:
    """A recorded frame as a warp source: its camera, image and z-depth (metres; 0, NaN or +inf:
    no surface known there)."""

    K: np.ndarray
    camera_to_world: np.ndarray
    image: np.ndarray  # [H, W, C]
    depth: np.ndarray  # [H, W]
    tolerance: float | np.ndarray  # relative depth agreement that counts as ground (per pixel [H, W])
    ground: np.ndarray | None = field(default=None, repr=False)  # [H, W] bool, filled by the warper


@dataclass
class Warp:
    image: np.ndarray  # [H, W, C]: the fused warp where ``mask``, the raw render elsewhere
    mask: np.ndarray  # [H, W] bool: at least one source frame saw the pixel's ground point
    weight: np.ndarray  # [H, W]: the summed source weights


class GroundWarper:
    """Warps a package's recorded frames into shifted cameras (see the module docstring)."""

    def __init__(self, ground: GroundModel, sources: dict[int, SourceFrame], config: WarpConfig = DEFAULT):
        self.ground, self.sources, self.config = ground, sources, config
        for src in sources.values():
            src.ground = self._ground_mask(src)

    def _ground_mask(self, src: SourceFrame) -> np.ndarray:
        """Source pixels whose depth agrees with the ground model's."""
        h, w = src.depth.shape
        lam, hits = self.ground.intersect(src.camera_to_world[:3, 3], pixel_rays(src.K, src.camera_to_world, w, h))
        d = src.depth.reshape(-1).astype(np.float64)
        tol = np.broadcast_to(np.asarray(src.tolerance, dtype=np.float64), (h, w)).reshape(-1)
        ok = hits & measured(d) & (np.abs(d - lam) <= tol * lam)
        return ok.reshape(h, w)

    def ground_points(self, K, c2w, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
        """World points [H*W, 3] where each pixel's ray meets the ground, and which pixels are
        ground (below the horizon, z-depth within ``max_range_m``)."""
        origin = np.asarray(c2w, dtype=np.float64)[:3, 3]
        dirs = pixel_rays(K, c2w, width, height)
        lam, hits = self.ground.intersect(origin, dirs)
        hits &= lam <= self.config.max_range_m
        return origin + lam[:, None] * dirs, hits

    def warp(self, frame: int, K, c2w, width: int, height: int, raw: np.ndarray,
             rendered_depth: np.ndarray | None = None) -> Warp:
        """The recorded frames near ``frame`` (never ``frame`` itself) warped into camera ``c2w``;
        ``raw``: the render there, kept where no frame sees the ground; ``rendered_depth`` [H, W]
        (with 0 where the render is empty): ground pixels with something rendered in front are
        left to the render."""
        cfg = self.config
        X, ok = self.ground_points(K, c2w, width, height)
        if rendered_depth is not None:
            lam = (X - np.asarray(c2w, dtype=np.float64)[:3, 3]) @ np.asarray(c2w, dtype=np.float64)[:3, 2]
            d = rendered_depth.reshape(-1).astype(np.float64)
            ok &= (d <= 0) | (d >= (1.0 - cfg.occluder_margin) * lam)
        idx = np.flatnonzero(ok)
        Xg = X[idx]
        channels = raw.shape[2]
        acc = np.zeros((len(idx), channels))
        wsum = np.zeros(len(idx))
        for s in range(frame - cfg.radius, frame + cfg.radius + 1):
            if s == frame or s not in self.sources:
                continue
            colour, seen = _sample(self.sources[s], Xg)
            w = np.exp(-abs(s - frame) / cfg.falloff_frames)
            acc[seen] += w * colour[seen]
            wsum[seen] += w
        weight = np.zeros(width * height)
        weight[idx] = wsum
        out = np.array(raw, dtype=np.float64).reshape(-1, channels)
        seen = wsum > 0
        out[idx[seen]] = acc[seen] / wsum[seen, None]
        return Warp(out.reshape(height, width, channels).astype(raw.dtype), (weight > 0).reshape(height, width),
                    weight.reshape(height, width))


def _sample(src: SourceFrame, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bilinear colours of world points ``X`` in ``src`` and where all four texels show the ground."""
    h, w = src.depth.shape
    w2c = conventions.invert_rigid(src.camera_to_world)
    pc = X @ w2c[:3, :3].T + w2c[:3, 3]
    z = pc[:, 2]
    front = z > 1e-6
    uv = pc[:, :2] / np.where(front, z, 1.0)[:, None] @ np.asarray(src.K, dtype=np.float64)[:2, :2].T \
        + np.asarray(src.K, dtype=np.float64)[:2, 2]
    x = uv[:, 0] - conventions.PIXEL_CENTER_OFFSET
    y = uv[:, 1] - conventions.PIXEL_CENTER_OFFSET
    inside = front & (x >= 0) & (x <= w - 1) & (y >= 0) & (y <= h - 1)
    x = np.where(inside, x, 0.0)
    y = np.where(inside, y, 0.0)
    x0 = np.minimum(np.floor(x).astype(np.int64), max(w - 2, 0))
    y0 = np.minimum(np.floor(y).astype(np.int64), max(h - 2, 0))
    x1, y1 = np.minimum(x0 + 1, w - 1), np.minimum(y0 + 1, h - 1)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    g = src.ground
    seen = inside & g[y0, x0] & g[y0, x1] & g[y1, x0] & g[y1, x1]
    img = src.image
    colour = ((1 - fy) * ((1 - fx) * img[y0, x0] + fx * img[y0, x1])
              + fy * ((1 - fx) * img[y1, x0] + fx * img[y1, x1]))
    return colour, seen


def package_warper(manifest, cam, gaussians=None, config: WarpConfig = DEFAULT) -> GroundWarper:
    """The warper for camera ``cam`` of a package: the ground fitted to ``background.points``
    (else, and where they give none, the splat centres of ``gaussians``; then the fallbacks of
    :meth:`GroundModel.fit`, the package's ground among them when it was imported), every recorded
    frame a source, with the package's depth where it measured, else the depth ``gaussians`` render."""
    from ..io.images import read_image
    from ..io.points import read_points

    where = manifest.path or manifest.root
    splats = None if gaussians is None else gaussians.means
    if manifest.background_points:
        points = read_points(manifest.resolve(manifest.background_points, "background.points"))[0]
    elif splats is not None:
        points, splats = splats, None
    else:
        raise WarpError(f"{where}: the geometry-guided warp fits the ground to background.points or the "
                        "background splats; the package has neither")
    imported = WORLD_GROUND if "ground_fit" in (manifest.source or {}) else None
    try:
        ground = GroundModel.fit(points, [cf.camera_to_world for cf in cam.frames], config, splats=splats,
                                 package_ground=imported)
    except WarpError as e:
        raise WarpError(f"{where}: {e}") from None
    renderer = None
    sources = {}
    for fi, cf in enumerate(cam.frames):
        if not cf.image:
            continue
        image = read_image(manifest.resolve(cf.image), channels=3)
        depth = read_depth(manifest, cam, fi)
        if depth is None and gaussians is None:
            raise WarpError(f"{where}: cameras.{cam.name}.frames[{fi}] has no depth and there are no background "
                            "splats to render it from: the geometry-guided warp needs one of them for occlusion")
        if depth is None:
            depth = np.full((cam.height, cam.width), UNMEASURED, np.float32)
        unmeasured = np.isnan(depth)
        if unmeasured.any() and gaussians is not None:
            from ..scene.camera import CameraView
            from ..splat.render import SplatRenderer

            renderer = renderer or SplatRenderer(gaussians)
            depth = np.where(unmeasured, renderer.depth(CameraView.of_frame(cam, fi), config.min_alpha), depth)
        tol = np.where(unmeasured, config.rendered_depth_tolerance, config.depth_tolerance)
        sources[fi] = SourceFrame(cf.K, cf.camera_to_world, image, depth, tol)
    if not sources:
        raise WarpError(f"{where}: camera {cam.name!r} has no recorded images to warp")
    return GroundWarper(ground, sources, config)
