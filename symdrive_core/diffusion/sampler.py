"""Images in, image out: one conditional flow sample with any restorer.

``restore_image`` encodes the two side views (and the initialisation view), runs the Euler
sampler from step ``n_start`` and decodes. Images are [B, 3, H, W] tensors in [0, 1];
``to_tensor`` / ``to_numpy`` convert from and to the [H, W, 3] arrays the rest of the toolkit uses.
"""

from __future__ import annotations

import numpy as np
import torch

from . import flow
from .config import SamplerConfig

DEFAULT = SamplerConfig()


def to_tensor(image: np.ndarray) -> torch.Tensor:
    """[H, W, 3] (or [N, H, W, 3]) array -> [B, 3, H, W] float32."""
    t = torch.as_tensor(np.ascontiguousarray(image, dtype=np.float32))
    t = t[None] if t.ndim == 3 else t
    return t.permute(0, 3, 1, 2).contiguous()


def to_numpy(images: torch.Tensor) -> np.ndarray:
    """[1, 3, H, W] -> [H, W, 3] (or [B, H, W, 3] for B > 1) float32."""
    out = images.detach().permute(0, 2, 3, 1).cpu().numpy().astype(np.float32)
    return out[0] if out.shape[0] == 1 else out


# Largest channel spread (max - min over R, G, B, any pixel) of an input that counts as grey: half
# an 8-bit level. A grey image has none, a reconstruction fitted to grey images renders within
# float error of none, and any 8-bit colour differs by a whole level.
GREY_SPREAD = 0.5 / 255


def is_grey(*images: torch.Tensor | None) -> bool:
    """Whether every given image [B, 3, H, W] is grey (see ``GREY_SPREAD``)."""
    return all(float((x.amax(dim=1) - x.amin(dim=1)).max()) <= GREY_SPREAD for x in images if x is not None)


def greyed(images: torch.Tensor) -> torch.Tensor:
    """[B, 3, H, W] with each channel the mean of the three (the luminance the image carries)."""
    return images.mean(dim=1, keepdim=True).expand_as(images).contiguous()


def generator(seed: int) -> torch.Generator:
    return torch.Generator().manual_seed(int(seed))


@torch.no_grad()
def restore_image(
    restorer,
    left: torch.Tensor,
    right: torch.Tensor,
    init: torch.Tensor | None,
    config: SamplerConfig = DEFAULT,
    guide: torch.Tensor | None = None,
) -> torch.Tensor:
    """The centre view between ``left`` and ``right``; ``init`` seeds the start at ``n_start``;
    ``guide`` [B, 4, H, W] (warp and mask at the target camera) reaches restorers that take one.
    The result moves from ``init`` by the sampler's (or the restorer's) ``strength`` share of the
    restorer's correction (:mod:`.strength`), and keeps the guide's warp where its mask is set
    unless the sampler (or the restorer) says otherwise (``keep_warp``).

    From grey inputs the result is grey, their channel mean: nothing in them says what colour the
    view has, yet a restorer trained on colour streets paints a cast of about 1/255 and colour
    grain from the per-channel noise into them."""
    if config.n_start > 0 and init is None:
        raise ValueError("n_start > 0 needs an initialisation image")
    noise_free = config.noise_free and config.n_start > 0  # from step 0 the start is the noise itself
    lat = restorer.latent
    zl, zr = lat.encode(left), lat.encode(right)
    ts = flow.timesteps(config.steps, restorer.time_shift(zl.shape))
    z0 = lat.encode(init) if init is not None else torch.zeros_like(zl)
    zg = restorer.encode_guide(guide) if guide is not None and getattr(restorer, "guide_channels", 0) else None
    k = 1 if noise_free else max(1, int(config.samples))
    if k > 1:
        zl, zr, z0 = (x.repeat_interleave(k, dim=0) for x in (zl, zr, z0))
        zg = None if zg is None else zg.repeat_interleave(k, dim=0)
    if noise_free:
        z = flow.noised(z0, 0.0, float(ts[config.n_start]))
    else:
        z = flow.start_state(z0, ts, config.n_start, generator(config.seed))
    velocity = restorer.velocity
    if config.max_memory_gib is not None:
        from .tiling import tiled_velocity

        velocity = tiled_velocity(restorer, z.shape, config.tiling())
    z = flow.euler(lambda zt, t: velocity(zt, t, zl, zr, zg) if zg is not None else velocity(zt, t, zl, zr),
                   z, ts, start=config.n_start)
    out = lat.decode(z)
    out = out.reshape(-1, k, *out.shape[1:]).mean(dim=1) if k > 1 else out
    if init is not None:
        out = toward(init, out, restoring_strength(restorer, config))
    if zg is not None and keeps_warp(restorer, config):
        out = kept_warp(out, guide)
    return greyed(out) if is_grey(left, right, init) else out


def kept_warp(restored: torch.Tensor, guide: torch.Tensor) -> torch.Tensor:
    """``restored`` [B, 3, H, W] with the guide's warp (its first three channels) where its mask (the fourth) is set."""
    guide = guide.to(restored.device, restored.dtype)
    mask = guide[:, 3:4]
    return mask * guide[:, :3] + (1.0 - mask) * restored


def restoring_strength(restorer, config: SamplerConfig = DEFAULT) -> float:
    """The sampler's ``strength``, else the restorer's (fitted by adaptation), else 1."""
    return float(config.strength if config.strength is not None else getattr(restorer, "strength", 1.0))


def keeps_warp(restorer, config: SamplerConfig = DEFAULT) -> bool:
    """The sampler's ``keep_warp``, else the restorer's (chosen by adaptation), else True."""
    return bool(config.keep_warp if config.keep_warp is not None else getattr(restorer, "keep_warp", True))


def toward(start: torch.Tensor, restored: torch.Tensor, strength: float) -> torch.Tensor:
    """``start + strength * (restored - start)`` in [0, 1]; ``restored`` itself at strength 1."""
    if strength == 1.0:
        return restored
    start = start.to(restored.device, restored.dtype)  # a latent restorer decodes on its own device
    return (start + strength * (restored - start)).clamp(0.0, 1.0)
