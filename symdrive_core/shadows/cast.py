"""The shadow an inserted vehicle casts on the ground, from its own Gaussians.

Sunlight is parallel, so the shadow on the ground plane is the vehicle's Gaussians projected
along the sun direction onto that plane. The projection is affine, so each 3D Gaussian becomes
a 2D Gaussian there, and its value at a ground point equals the largest response of the 3D
Gaussian along that point's ray to the sun (minimising a quadratic form along a line leaves the
form of the projected covariance). Compositing the projected Gaussians with the rasterizer gives
the occlusion ``1 - prod(1 - alpha_i)`` on a ground grid: a shadow map. Each camera pixel whose
ray meets the ground reads the map at its ground point, and the background there keeps the
fraction ``shadow_ratio`` of its linear-light radiance (the skylight share of sun plus sky)
where the occlusion is 1, blended linearly below. A pixel whose rendered surface stands well
above the ground along its ray (a parked car, a wall in front of the ground point) shows
something the plane does not model, and is left lit; so are the vehicle's own pixels.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from .. import conventions
from ..conventions import sun_above_horizon
from ..gaussians import Gaussians
from ..scene import Pose
from ..scene.place import place
from ..splat.constants import ALPHA_MAX, ALPHA_THRESHOLD
from ..splat.frozen_view import FrozenView
from ..splat.projection import quat_to_rotmat
from ..splat.rasterizer import RasterizePixels, bin_gaussians
from .region import ground_hits, shadow_polygon, vehicle_ground_z

MAP_MAX_PIXELS = 1024  # longest side of the shadow map
MAP_MIN_CELL_M = 0.01
MAP_BLUR_CELLS2 = 0.3  # added to each projected covariance (cells^2): a flat splat edge-on to the sun stays finite
# What a pixel shows counts as ground up to this height (m): kerbs, and the depth a splat render
# gives a road seen at a grazing angle (centre depths, biased towards the camera).
GROUND_HEIGHT_TOLERANCE = 0.5
SHADOW_WINDOW_MARGIN_M = 1.0  # room around the box's shadow for splats past the box and soft edges
EXTENT_SIGMAS = 3.5  # o * exp(-3.5^2 / 2) < 1/255 for any opacity: the cut drops nothing the kernel keeps


@dataclass(frozen=True)
class ShadowMap:
    """Occlusion of the sun on a ground plane, as a grid in the world's (x, y) or, with
    ``to_map``, in another frame on that plane (a vehicle's own, for a shadow that moves with it)."""

    occlusion: np.ndarray | torch.Tensor  # [rows, cols] in [0, 1]; row = y, col = x of the map's frame
    origin: np.ndarray  # (x, y) of the map's corner in its frame (pixel edge, not centre)
    cell: float  # metres per map pixel
    ground_z: float
    to_map: np.ndarray | None = None  # [2, 3]: world (x, y, 1) on the ground -> the map's (x, y); None: the world's

    def sample(self, xy: np.ndarray):
        """Bilinear occlusion at world ground points [..., 2]; 0 outside the map, fading to it over
        the border cell. A tensor occlusion gives a tensor, in its graph (a learnt map fits through
        it), else float64 numpy."""
        p = np.asarray(xy, dtype=np.float64)
        if self.to_map is not None:
            p = p @ self.to_map[:, :2].T + self.to_map[:, 2]
        rows, cols = self.occlusion.shape
        unit = 2.0 * (p - self.origin) / (self.cell * np.array([cols, rows])) - 1.0  # grid_sample's [-1, 1] edges
        occ = self.occlusion if torch.is_tensor(self.occlusion) else torch.from_numpy(
            np.asarray(self.occlusion, dtype=np.float64))
        grid = torch.from_numpy(unit.reshape(1, -1, 1, 2)).to(occ.dtype)
        out = torch.nn.functional.grid_sample(occ[None, None], grid, mode="bilinear", padding_mode="zeros",
                                              align_corners=False).reshape(p.shape[:-1])
        return out if torch.is_tensor(self.occlusion) else out.numpy()


def shadow_map(world_vehicle: Gaussians, sun_direction, ground_z: float, *, bounds=None,
               max_pixels: int = MAP_MAX_PIXELS, min_cell: float = MAP_MIN_CELL_M) -> ShadowMap | None:
    """The occlusion the world-placed Gaussians cast on ``z = ground_z``; None when the sun is down.

    ``bounds`` ((x0, y0), (x1, y1)) is the ground window to map; without it the window covers every
    Gaussian's footprint, which a single huge floater would stretch to a useless resolution."""
    s = sun_above_horizon(sun_direction)
    if s is None or len(world_vehicle) == 0:
        return None
    keep = world_vehicle.finite_mask() & (world_vehicle.opacities >= ALPHA_THRESHOLD)
    g = world_vehicle.subset(keep)
    if len(g) == 0:
        return None
    f64 = torch.float64
    # x -> x + ((ground_z - x_z) / s_z) s: drop each point along the sun ray onto the plane.
    M = torch.tensor([[1.0, 0.0, -s[0] / s[2]], [0.0, 1.0, -s[1] / s[2]]], dtype=f64)
    mu = torch.as_tensor(g.means, dtype=f64)
    R = quat_to_rotmat(torch.as_tensor(g.unit_quats, dtype=f64))
    RS = R * torch.as_tensor(g.scales, dtype=f64)[:, None, :]
    A = M @ RS  # [N, 2, 3]
    cov = A @ A.transpose(1, 2)
    xy = mu[:, :2] + ((ground_z - mu[:, 2:3]) / s[2]) * torch.as_tensor(s[:2], dtype=f64)
    if bounds is None:
        sd = torch.sqrt(torch.stack([cov[:, 0, 0], cov[:, 1, 1]], -1))
        lo = (xy - EXTENT_SIGMAS * sd).min(0).values.numpy()
        hi = (xy + EXTENT_SIGMAS * sd).max(0).values.numpy()
    else:
        lo, hi = (np.asarray(b, dtype=np.float64) for b in bounds)
    cell = max(float(np.max(hi - lo)) / max_pixels, min_cell)
    cols, rows = (int(np.ceil(v)) + 1 for v in (hi - lo) / cell)
    m2d = (xy - torch.as_tensor(lo, dtype=f64)) / cell
    c = cov / cell**2 + MAP_BLUR_CELLS2 * torch.eye(2, dtype=f64)
    det = c[:, 0, 0] * c[:, 1, 1] - c[:, 0, 1] ** 2
    conics = torch.stack([c[:, 1, 1], -c[:, 0, 1], c[:, 0, 0]], -1) / det[:, None]
    reach = EXTENT_SIGMAS * torch.sqrt(torch.stack([c[:, 0, 0], c[:, 1, 1]], -1))
    radii = torch.ceil(torch.clamp(reach, max=float(4 * max(rows, cols)))).to(torch.int32)  # past the map: clipped
    bins = bin_gaussians(m2d, radii, -torch.as_tensor(g.means[:, 2], dtype=f64), cols, rows)
    opac = torch.as_tensor(np.minimum(g.opacities, ALPHA_MAX), dtype=f64)
    with torch.no_grad():
        _, alpha, _ = RasterizePixels.apply(m2d, conics, opac, torch.zeros(len(g), 1, dtype=f64),
                                            torch.zeros(len(g), dtype=torch.int64), 0, bins, cols, rows,
                                            ALPHA_THRESHOLD)
    return ShadowMap(alpha.numpy(), lo, cell, float(ground_z))


def shadow_window(pose: Pose, wlh, sun_direction, margin: float = SHADOW_WINDOW_MARGIN_M):
    """Ground window ((x0, y0), (x1, y1)) of a vehicle's box shadow grown by ``margin`` metres
    (None when the sun is down): the map covers the car's shadow, not its stray Gaussians'."""
    hull = shadow_polygon(pose, wlh, sun_direction)
    if hull is None:
        return None
    return hull.min(0) - margin, hull.max(0) + margin


def occlusion_image(smap: ShadowMap, c2w: np.ndarray, K: np.ndarray, width: int, height: int,
                    surface_depth: np.ndarray | None = None):
    """Occlusion [H, W] at the ground point of every pixel centre: 0 where the ray misses the
    ground, or where ``surface_depth`` (camera z of what the pixel shows, 0 for nothing) puts
    the surface more than :data:`GROUND_HEIGHT_TOLERANCE` above the ground. float32 numpy, or a
    tensor in the graph of a tensor map."""
    xy, hit = ground_hits(c2w, K, width, height, smap.ground_z)
    shows_ground = hit
    if surface_depth is not None:
        c2w = np.asarray(c2w, dtype=np.float64)
        points = np.concatenate([xy, np.full(xy.shape[:-1] + (1,), smap.ground_z)], -1).reshape(-1, 3)
        ground_depth = conventions.project_points(points, conventions.invert_rigid(c2w), K)[1].reshape(xy.shape[:-1])
        depth = np.asarray(surface_depth, dtype=np.float64)
        # along one ray height is linear in camera z: the camera's height, scaled down to the ground's
        fraction = np.divide(depth, ground_depth, out=np.ones_like(depth), where=hit & (ground_depth > 0))
        above = (c2w[2, 3] - smap.ground_z) * (1.0 - fraction)
        shows_ground = hit & ((depth <= 0) | (above <= GROUND_HEIGHT_TOLERANCE))
    occ = smap.sample(xy)
    if torch.is_tensor(occ):
        return occ * torch.from_numpy(shows_ground).to(occ.dtype)
    return np.where(shows_ground, occ, 0.0).astype(np.float32)


@dataclass(frozen=True)
class CastShadow:
    """What one view needs to lay a vehicle's shadow on any render of it."""

    occlusion: np.ndarray  # [H, W] in [0, 1]
    background: np.ndarray  # the background alone, [H, W, 3]
    ratio: float

    def apply(self, image: np.ndarray, vehicle_alpha: np.ndarray) -> np.ndarray:
        return darken(image, self.background, vehicle_alpha, self.occlusion, self.ratio)


def union(layers):
    """``1 - prod(1 - a)`` over same-shaped coverages in [0, 1] (float64 numpy, or tensors in their
    graph): light passes each in turn."""
    through = None
    for a in layers:
        passed = 1.0 - (a.clamp(0.0, 1.0) if torch.is_tensor(a) else np.clip(np.asarray(a, dtype=np.float64), 0.0, 1.0))
        through = passed if through is None else through * passed
    if through is None:
        raise ValueError("union: no layers")
    return 1.0 - through


def combined_occlusion(maps: list[ShadowMap], c2w: np.ndarray, K: np.ndarray, width: int, height: int,
                       surface_depth: np.ndarray | None = None) -> np.ndarray:
    """Occlusion [H, W] of several vehicles' shadows."""
    if not maps:
        return np.zeros((height, width), np.float32)
    return union(occlusion_image(smap, c2w, K, width, height, surface_depth) for smap in maps).astype(np.float32)


def vehicle_shadow_map(vehicle: Gaussians, pose: Pose, wlh, sun_direction, *,
                       min_cell: float = MAP_MIN_CELL_M) -> ShadowMap | None:
    """The shadow map of ``vehicle`` (its own frame) standing at ``pose``; None when the sun is down."""
    return shadow_map(place(vehicle, pose), sun_direction, vehicle_ground_z(pose, wlh),
                      bounds=shadow_window(pose, wlh, sun_direction), min_cell=min_cell)


def vehicle_shadow(view: FrozenView, vehicle: Gaussians, pose: Pose, wlh, sun_direction,
                   ratio: float) -> CastShadow | None:
    """The shadow ``vehicle`` (its own frame) casts at ``pose`` in ``view``; None when the sun is down."""
    smap = vehicle_shadow_map(vehicle, pose, wlh, sun_direction)
    if smap is None:
        return None
    cam = view.camera
    background, depth = view.render_background_numpy()
    return CastShadow(occlusion_image(smap, cam.camera_to_world, cam.K, cam.width, cam.height, depth),
                      background, float(ratio))


def shaded(background: torch.Tensor, occlusion: torch.Tensor, shadow_ratio) -> torch.Tensor:
    """sRGB ``background`` [..., 3] with its linear radiance scaled by ``1 - (1 - shadow_ratio) *
    occlusion`` (occlusion [...]): the one shading rule, differentiable in the background and the
    ratio, so a reconstruction that lays recorded vehicles' shadows fits through it."""
    keep = 1.0 - (1.0 - shadow_ratio) * occlusion.clamp(0.0, 1.0)[..., None]
    x = background.clamp_min(0.0)
    lin = torch.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055).clamp_min(1e-12) ** 2.4)
    y = (lin * keep).clamp(0.0, 1.0)
    return torch.where(y <= 0.0031308, 12.92 * y, 1.055 * y.clamp_min(1e-12) ** (1.0 / 2.4) - 0.055)


def darken(image: np.ndarray, background: np.ndarray, vehicle_alpha: np.ndarray, occlusion: np.ndarray,
           shadow_ratio: float) -> np.ndarray:
    """``image`` with the shadow laid on its background: where the vehicle does not cover a pixel,
    the background's linear radiance is scaled by ``1 - (1 - shadow_ratio) * occlusion``."""
    if not 0.0 <= float(shadow_ratio) <= 1.0:
        raise ValueError(f"shadow_ratio must lie in [0, 1], got {shadow_ratio}")
    bg = np.asarray(background, dtype=np.float64)
    shade = shaded(torch.from_numpy(bg), torch.from_numpy(np.asarray(occlusion, dtype=np.float64)),
                   float(shadow_ratio)).numpy()
    uncovered = 1.0 - np.clip(np.asarray(vehicle_alpha, dtype=np.float64), 0.0, 1.0)[..., None]
    out = np.asarray(image, dtype=np.float64) + uncovered * (shade - bg)
    touched = occlusion > 0
    result = np.array(image, dtype=np.float32, copy=True)
    result[touched] = np.clip(out[touched], 0.0, 1.0)
    return result


def lay_shadows(image: np.ndarray, vehicle_alphas, background: np.ndarray, background_depth: np.ndarray,
                maps: list[ShadowMap], c2w: np.ndarray, K: np.ndarray, shadow_ratio: float):
    """(``image`` with the shadows of ``maps`` laid on its background, their occlusion [H, W]):
    ``background`` and ``background_depth`` are the same view without vehicles, ``vehicle_alphas``
    each vehicle's coverage (vehicles stay as rendered)."""
    height, width = background_depth.shape
    occlusion = combined_occlusion(maps, c2w, K, width, height, background_depth)
    if not (occlusion > 0).any():
        return image, occlusion
    alphas = list(vehicle_alphas)
    vehicles = union(alphas) if alphas else np.zeros_like(occlusion, np.float64)
    return darken(image, background, vehicles, occlusion, shadow_ratio), occlusion
