"""Colour/opacity-only fine-tune of an inserted vehicle against harmonized frames.

The paper fixes the vehicle's geometry and fits only what lighting changes: the SH coefficients
and the opacity logits of its Gaussians, with L1 + lambda (1 - SSIM) over every harmonized
placement. Means, scales and rotations are never handed to the optimiser and come back
bit-identical. Each view is projected once (:class:`~symdrive_core.splat.frozen_view.FrozenView`),
so every step only re-evaluates colours and back-propagates through compositing.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import torch
from tqdm import tqdm

from ..gaussians import Gaussians
from ..splat.frozen_view import FrozenView
from .config import FinetuneConfig
from .losses import photometric


@dataclass
class FinetuneSample:
    view: FrozenView  # the placement's camera window, projected once
    target: np.ndarray  # [H, W, 3] harmonized image of that window
    mask: np.ndarray  # [H, W] pixels the loss looks at (the vehicle and a thin ring)


@dataclass
class FinetuneResult:
    gaussians: Gaussians
    seconds: float
    steps: int
    loss_first: float
    loss_last: float


def finetune_colors(vehicle: Gaussians, samples: list[FinetuneSample], cfg: FinetuneConfig | None = None,
                    *, progress: bool = True) -> FinetuneResult:
    """Fit ``vehicle``'s SH and opacity logits to the samples' targets; geometry untouched."""
    cfg = cfg or FinetuneConfig()
    if not samples:
        raise ValueError("finetune_colors needs at least one harmonized placement")
    t0 = time.perf_counter()
    sh0 = torch.nn.Parameter(torch.as_tensor(vehicle.sh[:, :1].copy()))
    shN = torch.nn.Parameter(torch.as_tensor(vehicle.sh[:, 1:].copy()))
    logits = torch.nn.Parameter(torch.as_tensor(vehicle.opacity_logits.copy()))
    groups = [{"params": [sh0], "lr": cfg.lr_sh0}, {"params": [logits], "lr": cfg.lr_opacity}]
    if shN.shape[1]:
        groups.append({"params": [shN], "lr": cfg.lr_shN})
    opt = torch.optim.Adam(groups, eps=1e-15)
    data = [(s.view, torch.as_tensor(s.target, dtype=torch.float32), torch.as_tensor(s.mask, dtype=torch.float32))
            for s in samples]
    rng = np.random.default_rng(cfg.seed)
    order: list[int] = []
    losses = []
    for _ in tqdm(range(cfg.steps), desc="finetune", unit="step", disable=not progress):
        if not order:
            order = list(rng.permutation(len(data)))
        view, target, mask = data[order.pop()]
        rgb, _, _ = view.render(torch.cat([sh0, shN], 1), logits)
        loss = photometric(rgb, target, cfg.ssim_lambda, mask)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        losses.append(float(loss.detach()))
    out = Gaussians(vehicle.means.copy(), vehicle.quats.copy(), vehicle.log_scales.copy(),
                    logits.detach().numpy().astype(np.float32).copy(),
                    torch.cat([sh0, shN], 1).detach().numpy().astype(np.float32).copy(),
                    None if vehicle.normals is None else vehicle.normals.copy(), dict(vehicle.extra))
    k = max(1, len(data))
    return FinetuneResult(out, time.perf_counter() - t0, cfg.steps, float(np.mean(losses[:k])),
                          float(np.mean(losses[-k:])))
