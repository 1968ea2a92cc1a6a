"""The built-in restorer network: a small UNet over ``[z_-d ; z_t ; z_d]`` stacked on channels.

Why channel concatenation: the two conditions are views of the same street a few metres to
either side, so their content lies near the same pixels as the target's; a convolution sees
all three at once for the price of a wider first layer, while a token sequence would triple
the length of every attention. Why a UNet: it is fully convolutional, so it trains on small
random crops and runs at the full frame size, and on a CPU a 3x3 convolution is far cheaper
per pixel than attention. The receptive field (three downsamplings, ~150 px) covers the parallax
of a 0.5-1 m lateral step at this resolution.
"""

from __future__ import annotations

import math
from dataclasses import replace

import torch
import torch.nn.functional as F
from torch import nn

from .config import GUIDE_CHANNELS, UNetConfig


def time_embedding(t: torch.Tensor, dim: int) -> torch.Tensor:
    """Sinusoidal features of ``1000 t`` (t in [0, 1])."""
    half = dim // 2
    freqs = torch.exp(-math.log(10000.0) * torch.arange(half, dtype=torch.float32) / half)
    angles = 1000.0 * t.float()[:, None] * freqs[None]
    return torch.cat([angles.sin(), angles.cos()], dim=1)


class ResBlock(nn.Module):
    def __init__(self, cin: int, cout: int, tdim: int, groups: int):
        super().__init__()
        self.norm1 = nn.GroupNorm(min(groups, cin), cin)
        self.conv1 = nn.Conv2d(cin, cout, 3, padding=1)
        self.time = nn.Linear(tdim, cout)
        self.norm2 = nn.GroupNorm(min(groups, cout), cout)
        self.conv2 = nn.Conv2d(cout, cout, 3, padding=1)
        self.skip = nn.Conv2d(cin, cout, 1) if cin != cout else nn.Identity()

    def forward(self, x: torch.Tensor, temb: torch.Tensor) -> torch.Tensor:
        h = self.conv1(F.silu(self.norm1(x)))
        h = h + self.time(temb)[:, :, None, None]
        h = self.conv2(F.silu(self.norm2(h)))
        return h + self.skip(x)


class UNet(nn.Module):
    """``forward(z_t, t, cond_left, cond_right) -> velocity`` on [B, C, H, W] tensors.

    With ``output="skip"`` (the default) the network body ``F`` predicts a correction to the
    clean image rather than the velocity itself. With ``m = (cond_left + cond_right) / 2``,
    ``s = cond_sigma`` and ``D = (1 - t)^2 s^2 + t^2``::

        x0 = (s^2 (1 - t) z_t + t^2 m) / D + (s t / sqrt(D)) F,      v = (z_t - x0) / t

    The first term is the least-squares blend of the two estimates of the centre view, the
    noisy state (``z_t / (1 - t)``, noise ``t / (1 - t)``) and the condition mean (error ``s``):
    near ``t = 0`` it is ``z_t``, near ``t = 1`` it is ``m``. A network with a zero output layer
    therefore already returns the condition mean (the input itself when both conditions are the
    same render, as in single-view restoration) and removes no detail it cannot improve; training
    only has to learn the correction, scaled to unit variance (EDM-style preconditioning).
    """

    def __init__(self, config: UNetConfig = UNetConfig()):
        super().__init__()
        self.config = config
        c, w = config.image_channels, config.width
        widths = [w * m for m in config.mults]
        tdim = 4 * w
        self.time_mlp = nn.Sequential(nn.Linear(w, tdim), nn.SiLU(), nn.Linear(tdim, tdim))
        self.inp = nn.Conv2d(3 * c + config.guide_channels, widths[0], 3, padding=1)
        self.down = nn.ModuleList()
        self.downsample = nn.ModuleList()
        prev = widths[0]
        for i, wi in enumerate(widths):
            self.down.append(ResBlock(prev, wi, tdim, config.groups))
            prev = wi
            if i < len(widths) - 1:
                self.downsample.append(nn.Conv2d(wi, wi, 3, stride=2, padding=1))
        self.mid = ResBlock(prev, prev, tdim, config.groups)
        self.up = nn.ModuleList()
        for wi in reversed(widths):
            self.up.append(ResBlock(prev + wi, wi, tdim, config.groups))
            prev = wi
        self.out_norm = nn.GroupNorm(min(config.groups, prev), prev)
        self.out = nn.Conv2d(prev, c, 3, padding=1)
        nn.init.zeros_(self.out.weight)
        nn.init.zeros_(self.out.bias)
        if config.output not in ("skip", "v"):
            raise ValueError(f"UNet output must be 'skip' or 'v', got {config.output!r}")

    @property
    def multiple(self) -> int:
        return 2 ** (len(self.config.mults) - 1)

    def forward(
        self, z_t: torch.Tensor, t: torch.Tensor, cond_left: torch.Tensor, cond_right: torch.Tensor,
        guide: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """``guide`` [B, guide_channels, H, W]: required when the network has guide channels, and
        ignored when it has none (an unguided network runs the guided methods as it always did)."""
        h, w = z_t.shape[-2:]
        m = self.multiple
        pad = (0, (-w) % m, 0, (-h) % m)
        residual = self.config.output == "skip"
        tb = t.to(z_t.dtype).clamp(1e-4, 1.0).reshape(-1, 1, 1, 1)
        z_in = z_t
        if residual:
            sd = self.config.data_sigma
            z_in = z_t / torch.sqrt((1 - tb) ** 2 * sd**2 + tb**2)
        views = [cond_left, z_in, cond_right]
        if self.config.guide_channels:
            if guide is None:
                raise ValueError(f"this restorer takes a {self.config.guide_channels}-channel guide (warp and mask)")
            views.append(guide.to(z_t.dtype))
        x = F.pad(torch.cat(views, dim=1), pad, mode="replicate")
        if not self.training:
            # NHWC, oneDNN's preferred layout for convolutions: the same velocity to float rounding,
            # 1.75x faster on a 1080p frame on the CPU (scripts/bench_restorer_cpu.py); training
            # keeps NCHW so its runs replay bit for bit
            x = x.contiguous(memory_format=torch.channels_last)
        temb = self.time_mlp(time_embedding(t, self.config.width))
        x = self.inp(x)
        skips = []
        for i, block in enumerate(self.down):
            x = block(x, temb)
            skips.append(x)
            if i < len(self.downsample):
                x = self.downsample[i](x)
        x = self.mid(x, temb)
        for block in self.up:
            skip = skips.pop()
            if x.shape[-2:] != skip.shape[-2:]:
                x = F.interpolate(x, size=skip.shape[-2:], mode="nearest")
            x = block(torch.cat([x, skip], dim=1), temb)
        x = self.out(F.silu(self.out_norm(x)))[..., :h, :w].contiguous()
        if not residual:
            return x
        s2 = self.config.cond_sigma**2
        d = (1 - tb) ** 2 * s2 + tb**2
        mean = 0.5 * (cond_left + cond_right)
        x0 = (s2 * (1 - tb) * z_t + tb**2 * mean) / d + (self.config.cond_sigma * tb / torch.sqrt(d)) * x
        return (z_t - x0) / tb

    def loss_weight(self, t: torch.Tensor) -> torch.Tensor:
        """Per-sample weight on the squared velocity error that makes it the squared error of
        the network body's correction (unit target variance); ones for ``output="v"``."""
        if self.config.output != "skip":
            return torch.ones_like(t)
        s2 = self.config.cond_sigma**2
        tb = t.clamp(1e-4, 1.0)
        return ((1 - tb) ** 2 * s2 + tb**2) / s2


def with_guide(net: UNet, channels: int = GUIDE_CHANNELS) -> UNet:
    """``net`` with ``channels`` guide inputs whose first-layer weights are zero: it computes
    exactly what ``net`` does whatever the guide, so fine-tuning starts from the trained network
    and only learns what the guide adds."""
    if net.config.guide_channels:
        raise ValueError("the network already has guide channels")
    out = UNet(replace(net.config, guide_channels=channels))
    state = dict(net.state_dict())
    w = state["inp.weight"]
    state["inp.weight"] = torch.cat([w, w.new_zeros(w.shape[0], channels, *w.shape[2:])], dim=1)
    out.load_state_dict(state)
    return out
