"""Where the flow runs: pixels (the built-in model) or a VAE latent (Flux).

Both map [B, 3, H, W] images in [0, 1] to a space with roughly unit-scale values and back.
``factor`` is the spatial downsampling, used to bring pixel masks to the latent grid.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

FLUX_SCALE = 0.3611
FLUX_SHIFT = 0.1159


class PixelSpace:
    """Identity up to an affine map to [-1, 1]: no reconstruction error, nothing to load."""

    factor = 1
    channels = 3

    def encode(self, images: torch.Tensor) -> torch.Tensor:
        return images * 2.0 - 1.0

    def decode(self, z: torch.Tensor) -> torch.Tensor:
        return ((z + 1.0) * 0.5).clamp(0.0, 1.0)


class VAESpace:
    """A diffusers ``AutoencoderKL`` with Flux's latent normalisation ``(z - shift) * scale``.

    The encoder's mean is used (no sampling), so encoding is deterministic.
    """

    def __init__(self, vae):
        self.vae = vae.eval().requires_grad_(False)
        cfg = vae.config
        self.scale = float(getattr(cfg, "scaling_factor", None) or FLUX_SCALE)
        shift = getattr(cfg, "shift_factor", None)
        self.shift = float(FLUX_SHIFT if shift is None else shift)
        self.factor = 2 ** (len(cfg.block_out_channels) - 1)
        self.channels = int(cfg.latent_channels)

    def _param(self) -> torch.Tensor:
        return next(self.vae.parameters())

    @torch.no_grad()
    def encode(self, images: torch.Tensor) -> torch.Tensor:
        p = self._param()
        z = self.vae.encode((images * 2.0 - 1.0).to(p.device, p.dtype)).latent_dist.mode()
        return ((z - self.shift) * self.scale).float()

    @torch.no_grad()
    def decode(self, z: torch.Tensor) -> torch.Tensor:
        p = self._param()
        x = self.vae.decode((z / self.scale + self.shift).to(p.device, p.dtype)).sample
        return ((x.float() + 1.0) * 0.5).clamp(0.0, 1.0)


def latent_mask(mask: torch.Tensor, factor: int) -> torch.Tensor:
    """[B, 1, H, W] pixel mask -> latent grid; a latent cell is masked if any of its pixels is."""
    if factor == 1:
        return mask
    return F.max_pool2d(mask.float(), kernel_size=factor, stride=factor, ceil_mode=True)
