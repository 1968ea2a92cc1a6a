"""A background plus one actor seen by one camera, projected once, re-coloured many times.

Fine-tuning and the insertion baselines re-render the same views many times with only the actor's
colours and opacities changing. Geometry is frozen, so the EWA projection, the tile lists and the
background's colours are computed once per view; each render only re-evaluates the actor's SH
(view directions taken into the actor's frame, the renderer's convention, :mod:`.compose`) and
re-composites. Gradients reach the actor's SH coefficients and opacity logits only.

The actor is projected with opacity 1 so its tile footprint covers any opacity the optimisation
may reach; the compositing kernel still drops every alpha below the threshold.
"""

from __future__ import annotations

import numpy as np
import torch

from ..gaussians import Gaussians
from ..scene.camera import CameraView
from .constants import ALPHA_THRESHOLD
from .projection import project_gaussians
from .rasterizer import RasterizePixels, bin_gaussians
from .sh import sh_to_color
from .tensors import GaussianTensors


class FrozenView:
    def __init__(self, camera: CameraView, background: GaussianTensors | None, actor_world: Gaussians,
                 rotation: np.ndarray, *, background_color=(0.0, 0.0, 0.0), dtype=torch.float32):
        """``actor_world``: the actor's Gaussians placed in the world; ``rotation`` [3, 3]: its
        local-to-world rotation (the frame its SH is evaluated in)."""
        self.camera = camera
        self.sh_degree = actor_world.sh_degree
        W, H = camera.width, camera.height
        viewmat = torch.as_tensor(camera.world_to_camera, dtype=dtype)
        K = torch.as_tensor(camera.K, dtype=dtype)
        self.background_color = torch.as_tensor(background_color, dtype=dtype)
        with torch.no_grad():
            pv = project_gaussians(torch.as_tensor(actor_world.means, dtype=dtype),
                                   torch.as_tensor(actor_world.unit_quats, dtype=dtype),
                                   torch.as_tensor(actor_world.scales, dtype=dtype),
                                   torch.ones(len(actor_world), dtype=dtype), viewmat, K, W, H)
            self.actor_index = torch.nonzero(pv.visible, as_tuple=False).squeeze(1)
            R = torch.as_tensor(rotation, dtype=torch.float64)
            self.local_dirs = (pv.rel_means[self.actor_index] @ R).to(dtype)  # R^T (mu_w - c)
            parts = [(pv, self.actor_index)]
            if background is not None and len(background):
                pb = project_gaussians(background.means.to(dtype), background.quats.to(dtype),
                                       background.scales.to(dtype), background.opacities.to(dtype), viewmat, K, W, H)
                bi = torch.nonzero(pb.visible, as_tuple=False).squeeze(1)
                bg_sh = background.sh[bi].to(dtype)
                self.bg_colors = sh_to_color(background.sh_degree, bg_sh, pb.rel_means[bi]).to(dtype)
                self.bg_opacities = pb.opacities[bi]
                parts.insert(0, (pb, bi))
            else:
                self.bg_colors = torch.zeros(0, 3, dtype=dtype)
                self.bg_opacities = torch.zeros(0, dtype=dtype)
            self.means2d = torch.cat([p.means2d[i] for p, i in parts])
            self.conics = torch.cat([p.conics[i] for p, i in parts])
            self.depths = depths = torch.cat([p.depths[i] for p, i in parts])
            radii = torch.cat([p.radii[i] for p, i in parts])
            nb = self.bg_colors.shape[0]
            self.groups = torch.cat([torch.full((nb,), -1, dtype=torch.int64),
                                     torch.zeros(len(self.actor_index), dtype=torch.int64)])
            self.bins = bin_gaussians(self.means2d, radii, depths, W, H)

    @property
    def n_actor_visible(self) -> int:
        return int(self.actor_index.numel())

    def render(self, sh: torch.Tensor, opacity_logits: torch.Tensor):
        """(rgb [H,W,3], alpha [H,W], actor alpha [H,W]) for the actor's ``sh`` and logits."""
        idx = self.actor_index
        actor_colors = sh_to_color(self.sh_degree, sh[idx], self.local_dirs).to(self.bg_colors.dtype)
        colors = torch.cat([self.bg_colors, actor_colors])
        opac = torch.cat([self.bg_opacities, torch.sigmoid(opacity_logits[idx]).to(self.bg_opacities.dtype)])
        rgb, alpha, inst = RasterizePixels.apply(self.means2d, self.conics, opac, colors, self.groups, 1, self.bins,
                                                 self.camera.width, self.camera.height, ALPHA_THRESHOLD)
        rgb = rgb + (1.0 - alpha[..., None]) * self.background_color
        return rgb, alpha, inst[..., 0]

    def render_numpy(self, actor: Gaussians):
        """The view rendered with an asset's own colours, as numpy (rgb, actor alpha)."""
        with torch.no_grad():
            rgb, _, va = self.render(torch.as_tensor(actor.sh), torch.as_tensor(actor.opacity_logits))
        return rgb.numpy().astype(np.float32), va.numpy().astype(np.float32)

    def render_background_numpy(self) -> tuple[np.ndarray, np.ndarray]:
        """The view without the actor: (rgb [H, W, 3], expected depth [H, W], 0 where empty).
        The depth tells what a cast shadow may land on."""
        nb = self.bg_colors.shape[0]
        nv = self.means2d.shape[0] - nb
        dtype = self.bg_colors.dtype
        feats = torch.cat([torch.cat([self.bg_colors, self.depths[:nb, None]], 1), torch.zeros(nv, 4, dtype=dtype)])
        opac = torch.cat([self.bg_opacities, torch.zeros(nv, dtype=dtype)])
        with torch.no_grad():
            rgbd, alpha, _ = RasterizePixels.apply(self.means2d, self.conics, opac, feats, self.groups, 1, self.bins,
                                                   self.camera.width, self.camera.height, ALPHA_THRESHOLD)
        rgb = rgbd[..., :3] + (1.0 - alpha[..., None]) * self.background_color
        depth = torch.where(alpha > 0, rgbd[..., 3] / torch.clamp_min(alpha, 1e-12), torch.zeros_like(alpha))
        return rgb.numpy().astype(np.float32), depth.numpy().astype(np.float32)
