"""Where the sky is in a recorded view, so the reconstruction can start a far dome there.

A renderer's dense depth marks the sky (+inf). A drive without depth (SfM only) does not, and a
fit that starts with nothing there grows floaters in front of the cameras to explain the sky's
pixels, which every lateral view shows. There the sky is estimated as what lies above the horizon
and above the skyline the package's point cloud (triangulated from the images) draws in the view:
in each column of cells, the highest cell a point lands on, as seen over the neighbouring columns
(a wall without texture between two textured ones is not sky). A column no point lands on is sky
down to the horizon.

Sparse sensor depth marks no sky itself: its gaps are unmeasured. A scanner sees nothing above
its top beam (KITTI's: 2 degrees above the horizon), so the skyline its returns draw lets the
upper storeys of every building pass for sky; a dome of ordinary Gaussians started there painted
them and cost 0.8 dB of held-out PSNR. The reconstruction therefore starts that dome from the
same estimate (the depth left out) as broad Gaussians that keep their places and sizes
(``SkyConfig.sensor_dome_deg``; docs/results.md, "A sky where the depth does not mark it").
"""

from __future__ import annotations

import numpy as np

from ..conventions import WORLD_UP, invert_rigid, pixel_rays_camera, project_points
from ..scene.depth import is_sky
from .config import SkyConfig

NEAR_M = 0.5  # points nearer to a camera than this do not draw its skyline (the rig itself, noise)


def sky_mask(depth: np.ndarray | None, K: np.ndarray, world_to_camera: np.ndarray, width: int, height: int,
             cloud: np.ndarray | None, est: SkyConfig) -> np.ndarray:
    """[H, W] bool: the view's sky. From its ``depth`` (decoded: +inf sky, NaN unmeasured) where
    that is dense; none where it is sparse (a sensor's); without depth, from the horizon and the
    skyline of ``cloud`` ([N, 3] world points; None or empty: none)."""
    if depth is not None:
        return np.zeros((height, width), bool) if np.isnan(depth).any() else is_sky(depth)
    if cloud is None or len(cloud) == 0:
        return np.zeros((height, width), bool)
    ys, xs = np.mgrid[0:height, 0:width]
    rays = pixel_rays_camera(K, xs, ys)
    c2w = invert_rigid(world_to_camera)
    up = rays @ (c2w[:3, :3].T @ WORLD_UP)  # the rays' world up component, unnormalised
    above = up > np.sin(np.radians(est.min_elevation_deg)) * np.linalg.norm(rays, axis=-1)
    return above & (ys < _skyline(cloud, K, world_to_camera, width, height, est)[xs])


def _skyline(cloud: np.ndarray, K: np.ndarray, world_to_camera: np.ndarray, width: int, height: int,
             est: SkyConfig) -> np.ndarray:
    """[W] the first image row below the sky in each pixel column: the top of the highest cell a
    point lands on over the column's neighbourhood, less the margin (below the image where no
    point lands there)."""
    uv, z = project_points(cloud, world_to_camera, K)
    u, v = uv[:, 0], uv[:, 1]
    inside = (z > NEAR_M) & (u >= 0) & (u < width) & (v >= 0) & (v < height)
    cells_x = -(-width // est.cell_px)
    top = np.full(cells_x, height // est.cell_px + 1)  # per cell column, the highest cell row with a point
    np.minimum.at(top, (u[inside] // est.cell_px).astype(int), (v[inside] // est.cell_px).astype(int))
    n = est.neighbour_cells
    padded = np.pad(top, n, constant_values=top.max())
    top = np.min(np.stack([padded[k:k + cells_x] for k in range(2 * n + 1)]), 0)
    rows = (top - est.margin_cells) * est.cell_px
    return np.repeat(rows, est.cell_px)[:width]
