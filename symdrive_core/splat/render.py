"""Gaussians plus a view to an image: the one entry above the rasterizer.

Every render of Gaussians goes through here (the frozen-geometry views of fine-tuning excepted,
:mod:`.frozen_view`, which re-composite one projection many times):

* :func:`render_layers`: activated Gaussians (:class:`~.tensors.GaussianTensors`) as a background and
  rigidly moving actors (:mod:`.compose`), with per-actor instance channels: package frames, the
  simulator, benchmarks.
* :func:`render_params`: trainable parameters as the optimisers keep them (``quats`` unnormalised,
  ``log_scales``, ``opacity_logits``, SH split into ``sh0`` and ``shN``: the 3DGS layout), activated
  here and nowhere else.
* :class:`SplatRenderer`: stored Gaussians seen by a :class:`~symdrive_core.scene.camera.CameraView`
  (reconstruction scores, pairs, lateral chains, the simulator's restored views).
"""

from __future__ import annotations

import numpy as np
import torch

from ..conventions import FAR_PLANE, NEAR_PLANE
from ..gaussians import Gaussians, sh_coeff_count
from ..scene.camera import CameraView
from .compose import Layer, compose_layers
from .constants import ALPHA_THRESHOLD, EPS2D
from .rasterizer import rasterize
from .tensors import GaussianTensors

__all__ = ["Layer", "SplatRenderer", "activate", "params_from_gaussians", "render_layers", "render_params",
           "render_scene"]


def render_layers(layers: list[Layer], viewmat: torch.Tensor, K: torch.Tensor, width: int, height: int, *,
                  background=None, near: float = NEAR_PLANE, far: float = FAR_PLANE, eps2d: float = EPS2D,
                  antialiased: bool = False, alpha_threshold: float = ALPHA_THRESHOLD, extent="opacity",
                  backend: str = "auto", cull: bool = True) -> dict:
    """Render layers together in ONE rasterizer call. Returns dict(rgb [H,W,3], alpha [H,W,1],
    depth [H,W,1], instance [H,W,n_actors], actor_ids [ids of the instance channels, in first-seen
    order, background excluded], culled [actor ids culled by the frustum test], info)."""
    c = compose_layers(layers, viewmat, K, width, height, near=near, far=far, cull=cull,
                       sh_backend="torch" if backend == "torch" else "auto")
    dtype, G = c.dtype, len(c.actor_ids)
    # means are camera-relative (formed in float64, small now); the rasterizer sees a camera at the origin
    rgb, alpha, info = rasterize(c.means.to(dtype), c.quats.to(dtype), c.scales.to(dtype), c.opacities.to(dtype),
                                 c.colors.to(dtype), c.viewmat, K, width, height, background=background, near=near,
                                 far=far, eps2d=eps2d, antialiased=antialiased, render_depth=True,
                                 alpha_threshold=alpha_threshold, extent=extent, backend=backend, groups=c.groups,
                                 n_groups=G)
    inst = info.get("instance")
    if inst is None:
        inst = torch.zeros(height, width, G, dtype=rgb.dtype, device=rgb.device)
    return {"rgb": rgb, "alpha": alpha, "depth": info["depth"], "instance": inst, "actor_ids": c.actor_ids,
            "culled": c.culled, "info": info}


def render_scene(background: GaussianTensors | None, placed: list, view: CameraView, *, background_color=None,
                 antialiased: bool = False) -> dict:
    """A background plus actors ``placed`` as (Gaussians, Pose, instance id), seen by ``view``:
    :func:`render_layers`' dict."""
    sets = [g for g in (background, *(p[0] for p in placed)) if g is not None]
    device = sets[0].device if sets else (background_color.device if torch.is_tensor(background_color) else "cpu")
    layers = [] if background is None else [Layer(background)]
    for g, pose, instance_id in placed:
        layers.append(Layer(g, torch.as_tensor(pose.R, dtype=torch.float32, device=device),
                            torch.as_tensor(pose.translation, dtype=torch.float64, device=device), instance_id))
    return render_layers(layers, torch.as_tensor(view.world_to_camera, dtype=torch.float64, device=device),
                         torch.as_tensor(view.K, dtype=torch.float32, device=device), view.width, view.height,
                         background=background_color, antialiased=antialiased)


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


def activate(params: dict[str, torch.Tensor], sh_degree: int) -> GaussianTensors:
    """The parameters as the rasterizer takes them (in the graph: gradients reach ``params``), SH
    up to ``sh_degree``."""
    sh = params["sh0"] if sh_degree == 0 or "shN" not in params else torch.cat(
        [params["sh0"], params["shN"][:, : sh_coeff_count(sh_degree) - 1]], 1)
    quats = params["quats"] / params["quats"].norm(dim=1, keepdim=True).clamp_min(1e-12)
    return GaussianTensors(params["means"], quats, params["log_scales"].exp(), torch.sigmoid(params["opacity_logits"]),
                           sh, sh_degree)


def render_params(params: dict[str, torch.Tensor], K, viewmat, width: int, height: int,
                  sh_degree: int, render_depth: bool = False, **raster_options):
    """Activate the parameters and rasterize: (rgb [H,W,3], alpha [H,W,1], info).
    ``raster_options`` go to :func:`~.rasterizer.rasterize` (antialiased, extent, ...)."""
    g = activate(params, sh_degree)
    return rasterize(g.means, g.quats, g.scales, g.opacities, g.sh, viewmat, K, width, height,
                     sh_degree=sh_degree, render_depth=render_depth, **raster_options)


class SplatRenderer:
    """Renders one set of stored Gaussians at arbitrary views ([H, W, 3] float32 in [0, 1])."""

    def __init__(self, gaussians: Gaussians):
        self.degree = gaussians.sh_degree
        self.params = params_from_gaussians(gaussians, self.degree)

    def _render(self, view: CameraView, render_depth: bool):
        return render_params(self.params, torch.tensor(view.K, dtype=torch.float32),
                             torch.tensor(view.world_to_camera, dtype=torch.float32), view.width, view.height,
                             self.degree, render_depth=render_depth)

    @torch.no_grad()
    def __call__(self, view: CameraView) -> np.ndarray:
        rgb, _, _ = self._render(view, False)
        return rgb.clamp(0, 1).numpy()

    @torch.no_grad()
    def depth(self, view: CameraView, min_alpha: float = 0.5) -> np.ndarray:
        """Rendered z-depth [H, W] (float64), 0 where the render is less opaque than ``min_alpha``."""
        _, alpha, info = self._render(view, True)
        d = info["depth"][..., 0].double().numpy()
        return np.where(alpha[..., 0].numpy() >= min_alpha, d, 0.0)
