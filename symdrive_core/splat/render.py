"""Stored Gaussians to images: the one place that turns parameters into what the rasterizer takes.

Trainable parameters are kept raw (``quats`` unnormalised, ``log_scales``, ``opacity_logits``, SH
split into ``sh0`` and ``shN``: the 3DGS layout the optimisers step on); :func:`render_params`
activates them and calls :func:`~.rasterize.rasterize`, for training and for every renderer of
stored Gaussians (:class:`SplatRenderer`: reconstruction scores, pairs, lateral chains, the
simulator's restored views).
"""

from __future__ import annotations

import numpy as np
import torch

from .. import conventions
from ..gaussians import Gaussians, sh_coeff_count


def params_from_gaussians(g: Gaussians, sh_degree: int) -> dict[str, torch.nn.Parameter]:
    """Trainable float32 parameters of ``g`` up to ``sh_degree`` (missing SH bands are zero)."""
    k = sh_coeff_count(sh_degree)
    sh = np.zeros((len(g), k, 3), np.float32)
    m = min(k, g.sh.shape[1])
    sh[:, :m] = g.sh[:, :m]
    p = {"means": g.means, "quats": g.quats, "log_scales": g.log_scales,
         "opacity_logits": g.opacity_logits, "sh0": sh[:, :1]}
    if k > 1:
        p["shN"] = sh[:, 1:]
    return {n: torch.nn.Parameter(torch.tensor(np.ascontiguousarray(v), dtype=torch.float32)) for n, v in p.items()}


def render_params(params: dict[str, torch.Tensor], K, viewmat, width: int, height: int,
                  sh_degree: int, render_depth: bool = False, **raster_options):
    """Activate the parameters and rasterize: (rgb [H,W,3], alpha [H,W,1], info).
    ``raster_options`` go to :func:`symdrive_core.splat.rasterize` (antialiased, extent, ...)."""
    from .rasterize import rasterize

    sh = params["sh0"] if sh_degree == 0 or "shN" not in params else torch.cat(
        [params["sh0"], params["shN"][:, : sh_coeff_count(sh_degree) - 1]], 1)
    quats = params["quats"] / params["quats"].norm(dim=1, keepdim=True).clamp_min(1e-12)
    return rasterize(params["means"], quats, params["log_scales"].exp(),
                     torch.sigmoid(params["opacity_logits"]), sh, viewmat, K, width, height,
                     sh_degree=sh_degree, render_depth=render_depth, **raster_options)


class SplatRenderer:
    """Renders one set of Gaussians at arbitrary cameras ([H, W, 3] float32 in [0, 1])."""

    def __init__(self, gaussians: Gaussians):
        self.degree = gaussians.sh_degree
        self.params = params_from_gaussians(gaussians, self.degree)

    @torch.no_grad()
    def __call__(self, K, world_to_camera, width: int, height: int) -> np.ndarray:
        rgb, _, _ = render_params(self.params, torch.tensor(K, dtype=torch.float32),
                                  torch.tensor(world_to_camera, dtype=torch.float32), width, height, self.degree)
        return rgb.clamp(0, 1).numpy()

    @torch.no_grad()
    def depth(self, K, world_to_camera, width: int, height: int, min_alpha: float = 0.5) -> np.ndarray:
        """Rendered z-depth [H, W] (float64), 0 where the render is less opaque than ``min_alpha``."""
        _, alpha, info = render_params(self.params, torch.tensor(K, dtype=torch.float32),
                                       torch.tensor(world_to_camera, dtype=torch.float32), width, height,
                                       self.degree, render_depth=True)
        d = info["depth"][..., 0].double().numpy()
        return np.where(alpha[..., 0].numpy() >= min_alpha, d, 0.0)

    def shifted(self, K, camera_to_world, offset_m: float, width: int, height: int) -> np.ndarray:
        """The render at the camera moved ``offset_m`` along its own +x (right)."""
        c2w = conventions.lateral_shift(camera_to_world, offset_m)
        return self(K, conventions.invert_rigid(c2w), width, height)
