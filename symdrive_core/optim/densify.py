"""Adaptive density control for 3DGS training: clone, split and prune Gaussians while keeping
Adam's moment estimates aligned with the parameters they belong to.

Statistics follow Kerbl et al.: the norm of each Gaussian's view-space (NDC) position gradient,
averaged over the views in which it was visible. Small Gaussians with a large average gradient
are cloned (under-reconstruction), large ones are split in two, each 1/1.6 the size, sampled
from the parent (over-reconstruction). Nearly transparent and oversized Gaussians are pruned.
"""

from __future__ import annotations

import torch

from ..splat.projection import normalize_quats, quat_to_rotmat
from .config import DensifyConfig

SPLIT_SHRINK = 1.6


class GradStats:
    """Running sum of view-space gradient norms and visibility counts per Gaussian."""

    def __init__(self, n: int):
        self.sum = torch.zeros(n)
        self.count = torch.zeros(n)

    def add(self, ndc_grad_norm: torch.Tensor, visible: torch.Tensor) -> None:
        self.sum[visible] += ndc_grad_norm[visible]
        self.count[visible] += 1

    def mean(self) -> torch.Tensor:
        return self.sum / self.count.clamp_min(1)

    def reset(self, n: int) -> None:
        self.sum, self.count = torch.zeros(n), torch.zeros(n)


def ndc_gradient_norm(means2d_grad: torch.Tensor, width: int, height: int) -> torch.Tensor:
    """Norm of dL/d(NDC position) from the gradient of the projected centres in pixels
    (NDC spans W/2 and H/2 pixels per unit), the statistic 3DGS thresholds."""
    gu = means2d_grad[:, 0] * (0.5 * width)
    gv = means2d_grad[:, 1] * (0.5 * height)
    return torch.sqrt(gu * gu + gv * gv)


def _replace(opt: torch.optim.Optimizer, params: dict[str, torch.nn.Parameter], build) -> None:
    """Swap every parameter (and its Adam moments) for ``build(name, tensor)``'s result."""
    for group in opt.param_groups:
        old = group["params"][0]
        name = group["name"]
        new = torch.nn.Parameter(build(name, old.detach()))
        state = opt.state.pop(old, None)
        if state is not None:
            for key in ("exp_avg", "exp_avg_sq"):
                state[key] = build(None, state[key])
            opt.state[new] = state
        group["params"][0] = new
        params[name] = new


def prune(opt, params, keep: torch.Tensor) -> None:
    _replace(opt, params, lambda name, t: t[keep])


def append(opt, params, new: dict[str, torch.Tensor]) -> None:
    """Add Gaussians; their Adam moments start at zero."""
    m = len(new["means"])

    def build(name, t):
        return torch.cat([t, new[name] if name else t.new_zeros((m, *t.shape[1:]))])

    _replace(opt, params, build)


def densify_and_prune(opt, params, stats: GradStats, cfg: DensifyConfig, extent: float,
                      centre: torch.Tensor, generator: torch.Generator) -> dict[str, int]:
    """One density-control step; returns how many Gaussians were cloned, split and pruned."""
    with torch.no_grad():
        n = params["means"].shape[0]
        scales = params["log_scales"].exp()
        max_scale = scales.max(1).values
        grad = stats.mean()
        room = max(cfg.max_gaussians - n, 0)
        hot = grad >= cfg.grad_threshold
        if hot.sum() > room // 2:  # over budget: keep the hottest
            order = torch.argsort(grad, descending=True)[: room // 2]
            hot = torch.zeros_like(hot)
            hot[order] = True
        small = max_scale <= cfg.dense_fraction * extent
        clone, split = hot & small, hot & ~small

        new = {k: v.detach()[clone] for k, v in params.items()}
        idx = torch.nonzero(split).squeeze(1)
        if len(idx):
            std = scales[idx].repeat(2, 1)
            rot = quat_to_rotmat(normalize_quats(params["quats"][idx])).repeat(2, 1, 1)
            offset = torch.randn(std.shape, generator=generator) * std
            children = {k: v.detach()[idx].repeat(2, *[1] * (v.dim() - 1)) for k, v in params.items()}
            children["means"] = children["means"] + torch.einsum("nij,nj->ni", rot, offset)
            children["log_scales"] = children["log_scales"] - torch.log(torch.tensor(SPLIT_SHRINK))
            new = {k: torch.cat([new[k], children[k]]) for k in new}
        if len(new["means"]):
            append(opt, params, new)

        n_all = params["means"].shape[0]
        keep = torch.ones(n_all, dtype=torch.bool)
        keep[:n][split] = False  # split parents are replaced by their children
        opacity = torch.sigmoid(params["opacity_logits"].detach())
        dist = (params["means"].detach() - centre).norm(dim=1).clamp_min(1e-3)
        big = params["log_scales"].detach().exp().max(1).values > cfg.max_angular_size * dist
        keep &= (opacity >= cfg.min_opacity) & ~big
        pruned = int((~keep).sum()) - int(split.sum())
        prune(opt, params, keep)
        stats.reset(params["means"].shape[0])
    return {"cloned": int(clone.sum()), "split": int(split.sum()), "pruned": pruned}
