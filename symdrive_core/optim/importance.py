"""How much each Gaussian draws of the training views, and the pruning of those that draw least.

A Gaussian's importance is its blending weight ``alpha_i T_i`` summed over every pixel of every
training view: the share of the images it paints. Once density control has ended, a fit holds
many Gaussians that paint almost nothing (hidden behind others, nearly transparent, or a few
pixels wide), and each still costs projection, binning and compositing in every later step;
removing the least important few, with the iterations left to recover, makes those steps cheaper
(LightGaussian and Mini-Splatting prune by this score).

The weights come from the rasterizer's own backward pass: rendered with the colour 1 for every
Gaussian in one channel, the gradient of the image's sum with respect to Gaussian i's colour is
exactly its summed blending weight, the same decisions (threshold, transmittance stop) as every
training render.
"""

from __future__ import annotations

import torch

from ..splat.compose import compose_layers
from ..splat.rasterizer import rasterize


def blending_weights(parts, views, degree: int, cameras=None) -> list[torch.Tensor]:
    """Per part (``reconstruct.Part``), float64 ``[N]``: each Gaussian's blending weight summed over
    ``views``' pixels, as the fit renders each view (its parts present at the frame, placed where the
    fit places them, seen from the corrected camera where ``cameras`` refines them)."""
    from .camera_refine import corrected_layers

    totals = [torch.zeros(len(p.params["means"]), dtype=torch.float64) for p in parts]
    index = {id(p): i for i, p in enumerate(parts)}
    for view in views:
        present = [p for p in parts if p.present(view.frame)]
        with torch.no_grad():
            layers = [p.layer(view.frame, degree) for p in present]
            if cameras is not None:
                layers = corrected_layers(layers, cameras.world_inverse(view.frame))
            c = compose_layers(layers, view.viewmat.double(), view.K, view.width, view.height, cull=False)
        ones = torch.ones(len(c.means), 1, dtype=c.dtype, requires_grad=True)
        rgb, _, _ = rasterize(c.means.to(c.dtype), c.quats, c.scales, c.opacities, ones, c.viewmat, view.K,
                              view.width, view.height)
        rgb.sum().backward()
        row = 0
        for p in present:
            n = len(p.params["means"])
            totals[index[id(p)]] += ones.grad[row:row + n, 0].double()
            row += n
    return totals


def least_important(weights: torch.Tensor, fraction: float) -> torch.Tensor:
    """``[N]`` bool: the ``round(fraction * N)`` Gaussians of lowest ``weights`` (ties broken by
    index, so the count is exact), never all of them: the most important one stays, so a part
    pruned by a fraction of 1 still renders."""
    n = len(weights)
    drop = torch.zeros(n, dtype=torch.bool)
    k = min(n - 1, round(fraction * n))
    if k > 0:
        drop[torch.argsort(weights, stable=True)[:k]] = True
    return drop
