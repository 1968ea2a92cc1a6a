"""Photometric losses used by every optimisation stage: L1 + lambda * (1 - SSIM)."""

from __future__ import annotations

import torch

from ..metrics import ssim_map


def l1(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
    err = (pred - target).abs()
    if mask is None:
        return err.mean()
    m = mask if mask.ndim == 3 else mask[..., None]
    return (err * m).sum() / (m.sum() * pred.shape[-1]).clamp_min(1.0)


def ssim_loss(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
    s = ssim_map(pred, target)
    if mask is None:
        return 1.0 - s.mean()
    m = mask[..., 0] if mask.ndim == 3 else mask
    return 1.0 - (s * m).sum() / m.sum().clamp_min(1.0)


def photometric(pred, target, lam: float = 0.2, mask=None) -> torch.Tensor:
    """(1 - lam) * L1 + lam * (1 - SSIM), the 3DGS loss (lam = 0.2)."""
    return (1.0 - lam) * l1(pred, target, mask) + lam * ssim_loss(pred, target, mask)
