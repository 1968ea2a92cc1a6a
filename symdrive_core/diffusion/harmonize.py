"""Training-free harmonization of an inserted vehicle: RePaint with the restorer.

The restorer sees the inserted render on both sides, ``[z_insert ; z_t ; z_insert]``. Only the
evolving region (vehicle mask, plus the shadow region the caller adds where the scene has a
sun) is sampled; after every sampler step everything else is reset to the input render noised
to the current level, with fresh noise as RePaint does. Optional resampling jumps go back up
``jump_length`` steps ``resamples - 1`` times per jump point, re-noising with the exact
flow-matching transition (:func:`.flow.renoise`) so the marginals stay those of the schedule.
The last step lands on ``t = 0``, where the reset is ``x0`` itself, and the decoded result is
pasted into a copy of the input only inside the region: every other pixel comes back
bit-identical, also behind a VAE.
"""

from __future__ import annotations

import numpy as np
import torch

from . import flow
from .latent import latent_mask
from .sampler import SamplerConfig, generator, to_tensor


def repaint_moves(steps: int, start: int, jump_length: int = 0, resamples: int = 1) -> list[tuple[int, int]]:
    """The walk over schedule indices: ``(i, i + 1)`` denoises, ``(i, i - jump_length)`` jumps back."""
    if jump_length < 0 or resamples < 1:
        raise ValueError("jump_length must be >= 0 and resamples >= 1")
    left = {}
    if jump_length > 0 and resamples > 1:
        left = {j: resamples - 1 for j in range(start + jump_length, steps, jump_length)}
    moves, i = [], start
    while i < steps:
        moves.append((i, i + 1))
        i += 1
        if left.get(i, 0) > 0:
            left[i] -= 1
            moves.append((i, i - jump_length))
            i -= jump_length
    return moves


@torch.no_grad()
def harmonize(
    restorer,
    image: np.ndarray,
    region: np.ndarray,
    *,
    steps: int = SamplerConfig.steps,
    n_start: int = SamplerConfig.n_start,
    seed: int = 0,
    jump_length: int = 0,
    resamples: int = 1,
    samples: int = 1,
    max_memory_gib: float | None = None,
    tile: int = 256,
    tile_overlap: int = 32,
) -> np.ndarray:
    """Harmonize ``image`` [H, W, 3] in [0, 1] inside ``region`` [H, W] (bool); a new array.

    ``n_start`` > 0 starts from the inserted render noised to that step, which keeps the
    vehicle's shape while re-drawing its shading. ``samples`` > 1 averages that many
    independent harmonizations (one batch), as ``SamplerConfig.samples`` does for restoration.
    ``max_memory_gib`` bounds one denoiser evaluation: beyond it samples, then overlapping tiles,
    are evaluated in turn (:mod:`.tiling`); the reset and the schedule stay global.
    """
    image = np.asarray(image)
    region = np.asarray(region, dtype=bool)
    if image.ndim != 3 or image.shape[:2] != region.shape:
        raise ValueError(f"harmonize: image {image.shape} and region {region.shape} must share H, W")
    if not region.any():
        return image.copy()
    lat = restorer.latent
    x = to_tensor(image)
    x0 = lat.encode(x).repeat_interleave(max(1, int(samples)), dim=0)
    m = (
        latent_mask(torch.from_numpy(region)[None, None].float(), lat.factor)[
            ..., : x0.shape[-2], : x0.shape[-1]
        ]
        > 0
    )
    ts = flow.timesteps(steps, restorer.time_shift(x0.shape))
    g = generator(seed)

    def reset(z: torch.Tensor, i: int) -> torch.Tensor:
        t = float(ts[i])
        known = x0 if t == 0.0 else flow.noised(x0, torch.randn(x0.shape, generator=g, dtype=x0.dtype), t)
        return torch.where(m, z, known)

    z = flow.start_state(x0, ts, n_start, g)
    velocity = restorer.velocity
    if max_memory_gib is not None:
        from .tiling import TileOptions, tiled_velocity

        velocity = tiled_velocity(restorer, z.shape, TileOptions(max_memory_gib, tile, tile_overlap))
    for i, j in repaint_moves(steps, n_start, jump_length, resamples):
        if j < i:
            z = flow.renoise(z, float(ts[i]), float(ts[j]), g)
            continue
        t, s = float(ts[i]), float(ts[j])
        z = z + (s - t) * velocity(z, torch.full((z.shape[0],), t, dtype=z.dtype), x0, x0)
        z = reset(z, j)
    out = lat.decode(z).mean(dim=0).permute(1, 2, 0).cpu().numpy()
    result = image.copy()
    result[region] = out[region].astype(image.dtype)
    return result
