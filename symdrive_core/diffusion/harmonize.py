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

Only the region evolves, so the sampler runs on crops around it (:func:`crop_boxes`): the
region's bounding box grown by ``crop_margin`` pixels of context, its edges on multiples of the
latent factor times the UNet's downsampling (so the crop sees the full image's stride-2 sampling
phase) or on the image's edge. Regions farther apart than twice the margin get a crop each when
that is fewer pixels than one crop of their union. The schedule keeps the full image's time shift
(Flux's depends on the latent size), so a crop changes what the network sees, not when.
"""

from __future__ import annotations

import numpy as np
import torch

from . import flow
from .latent import latent_mask
from .sampler import SamplerConfig, generator, to_tensor

# Pixels of context around the region's bounding box the sampler sees (None: the whole image).
# The shipped UNet's receptive field spans ~150 px, but on the demo street's held-out placements
# 16, 32 and 64 px score within 0.06 dB of the whole image's mean masked PSNR (per placement within
# 0.13 dB: another crop draws other noise), 32 px in 3.4x less time per frame (`symdrive bench
# accuracy-time`, knob "harmonize crop margin"); 32 rather than 16 keeps more of the scene around
# the vehicle in view.
CROP_MARGIN = 32


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


Box = tuple[int, int, int, int]
"""``(y0, y1, x0, x1)``: rows ``y0:y1`` and columns ``x0:x1``."""


def _runs(occupied: np.ndarray, gap: int) -> list[tuple[int, int]]:
    """``[start, end)`` runs of ``occupied`` joined across gaps of at most ``gap`` cells."""
    idx = np.flatnonzero(occupied)
    if idx.size == 0:
        return []
    cut = np.flatnonzero(np.diff(idx) > gap + 1)
    starts = np.concatenate([[idx[0]], idx[cut + 1]])
    ends = np.concatenate([idx[cut], [idx[-1]]]) + 1
    return list(zip(starts.tolist(), ends.tolist(), strict=True))


def _groups(region: np.ndarray, gap: int, y0: int = 0, x0: int = 0) -> list[Box]:
    """Bounding boxes of the region's parts separated by more than ``gap`` empty rows or columns
    (recursive XY cut: no labelling pass, and parts whose grown boxes would overlap stay one)."""
    cols = _runs(region.any(axis=0), gap)
    if len(cols) > 1:
        return [b for c0, c1 in cols for b in _groups(region[:, c0:c1], gap, y0, x0 + c0)]
    rows = _runs(region.any(axis=1), gap)
    if len(rows) > 1:
        return [b for r0, r1 in rows for b in _groups(region[r0:r1], gap, y0 + r0, x0)]
    if not rows:
        return []
    (r0, r1), (c0, c1) = rows[0], cols[0]
    return [(y0 + r0, y0 + r1, x0 + c0, x0 + c1)]


def _grow(box: Box, margin: int, align: int, height: int, width: int) -> Box:
    """``box`` grown by ``margin``, its edges moved out to multiples of ``align``, clipped to the image."""
    y0, y1, x0, x1 = box
    return (max(0, (y0 - margin) // align * align), min(height, -(-(y1 + margin) // align) * align),
            max(0, (x0 - margin) // align * align), min(width, -(-(x1 + margin) // align) * align))


def crop_boxes(region: np.ndarray, margin: int | None, align: int = 1) -> list[Box]:
    """The crops the sampler runs on for ``region`` [H, W]: each part's box grown by ``margin``
    and aligned to ``align`` (see the module docstring); one box of the union when that is no
    more pixels than the parts' boxes together, the whole image for ``margin`` None, none for an
    empty region."""
    region = np.asarray(region, dtype=bool)
    h, w = region.shape
    if not region.any():
        return []
    if margin is None:
        return [(0, h, 0, w)]
    parts = [_grow(b, margin, align, h, w) for b in _groups(region, 2 * margin)]
    union = (min(b[0] for b in parts), max(b[1] for b in parts), min(b[2] for b in parts), max(b[3] for b in parts))

    def area(b: Box) -> int:
        return (b[1] - b[0]) * (b[3] - b[2])

    return [union] if area(union) <= sum(map(area, parts)) else parts


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
    crop_margin: int | None = CROP_MARGIN,
    max_memory_gib: float | None = None,
    tile: int = 256,
    tile_overlap: int = 32,
) -> np.ndarray:
    """Harmonize ``image`` [H, W, 3] in [0, 1] inside ``region`` [H, W] (bool); a new array.

    ``n_start`` > 0 starts from the inserted render noised to that step, which keeps the
    vehicle's shape while re-drawing its shading. ``samples`` > 1 averages that many
    independent harmonizations (one batch), as ``SamplerConfig.samples`` does for restoration.
    ``crop_margin`` is the context around the region the sampler sees (None: the whole image).
    ``max_memory_gib`` bounds one denoiser evaluation: beyond it samples, then overlapping tiles
    of the crop, are evaluated in turn (:mod:`.tiling`); the reset and the schedule stay global.
    """
    from .tiling import model_multiple

    image = np.asarray(image)
    region = np.asarray(region, dtype=bool)
    if image.ndim != 3 or image.shape[:2] != region.shape:
        raise ValueError(f"harmonize: image {image.shape} and region {region.shape} must share H, W")
    lat = restorer.latent
    h, w = region.shape
    k = max(1, int(samples))
    # the full image's latent size (a VAE's stride-2 stages floor it): the schedule of the whole frame
    mu = restorer.time_shift((k, getattr(lat, "channels", image.shape[2]), h // lat.factor, w // lat.factor))
    ts = flow.timesteps(steps, mu)
    g = generator(seed)
    result = image.copy()
    for y0, y1, x0, x1 in crop_boxes(region, crop_margin, lat.factor * model_multiple(restorer)):
        sub = region[y0:y1, x0:x1]
        out = _sample(restorer, image[y0:y1, x0:x1], sub, ts, g, n_start, jump_length, resamples, k,
                      max_memory_gib, tile, tile_overlap)
        result[y0:y1, x0:x1][sub] = out[sub].astype(image.dtype)
    return result


def _sample(restorer, image, region, ts, g, n_start, jump_length, resamples, samples, max_memory_gib, tile,
            tile_overlap) -> np.ndarray:
    """RePaint on one crop: the decoded mean of ``samples`` harmonizations [h, w, 3]."""
    lat = restorer.latent
    x0 = lat.encode(to_tensor(image)).repeat_interleave(samples, dim=0)
    m = (
        latent_mask(torch.from_numpy(region)[None, None].float(), lat.factor)[
            ..., : x0.shape[-2], : x0.shape[-1]
        ]
        > 0
    )
    steps = len(ts) - 1

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
    return lat.decode(z).mean(dim=0).permute(1, 2, 0).cpu().numpy()
