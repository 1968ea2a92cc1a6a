"""Activated Gaussian parameters as torch tensors (the rasterizer's input form)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from ..gaussians import Gaussians


@dataclass
class GaussianTensors:
    means: torch.Tensor  # [N, 3] metres
    quats: torch.Tensor  # [N, 4] unit wxyz (the rasterizer normalises again; zero -> identity)
    scales: torch.Tensor  # [N, 3] (exp of log scales)
    opacities: torch.Tensor  # [N] in [0, 1]
    sh: torch.Tensor  # [N, K, 3]
    sh_degree: int

    def __len__(self) -> int:
        return int(self.means.shape[0])

    @property
    def device(self) -> torch.device:
        return self.means.device

    @property
    def dtype(self) -> torch.dtype:
        return self.means.dtype

    @staticmethod
    def from_gaussians(g: Gaussians, device="cpu", dtype=torch.float32) -> GaussianTensors:
        def t(a):
            return torch.as_tensor(np.ascontiguousarray(a), device=device).to(dtype)

        return GaussianTensors(means=t(g.means), quats=t(g.unit_quats), scales=t(g.scales),
                               opacities=t(g.opacities), sh=t(g.sh), sh_degree=g.sh_degree)

    def to(self, device=None, dtype=None) -> GaussianTensors:
        def m(x):
            return x.to(device=device if device is not None else x.device, dtype=dtype or x.dtype)

        return GaussianTensors(m(self.means), m(self.quats), m(self.scales), m(self.opacities), m(self.sh),
                               self.sh_degree)

    def subset(self, index) -> GaussianTensors:
        return GaussianTensors(self.means[index], self.quats[index], self.scales[index],
                               self.opacities[index], self.sh[index], self.sh_degree)

    def local_bounds(self, sigmas: float = 3.0) -> tuple[torch.Tensor, torch.Tensor]:
        """Axis-aligned box [lo, hi] of the means padded by ``sigmas`` times the largest scale."""
        if len(self) == 0:
            z = torch.zeros(3, dtype=torch.float64)
            return z, z
        with torch.no_grad():
            m = self.means.detach().double()
            finite = torch.isfinite(m).all(1)
            m = m[finite] if bool(finite.any()) else torch.zeros(1, 3, dtype=torch.float64)
            s = self.scales.detach().double()
            s = s[torch.isfinite(s).all(1)]
            pad = sigmas * float(s.abs().max()) if s.numel() else 0.0
            return (m.min(0).values - pad).cpu(), (m.max(0).values + pad).cpu()
