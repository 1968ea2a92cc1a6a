"""How much of the restorer's correction a drive can trust, fitted on the drive's own frames.

The restorer moves its start (the warp, or the render) toward what the streets it learnt from
look like. Off those streets part of that move is wrong: on a Cycles street it never saw, the
adapted guided restorer took up to 0.7 dB from the warp it started from within 2 m, while on a
real drive its full correction is what helps (docs/results.md). The view a sampler returns is
therefore ``start + s * (restored - start)``, and an adaptation fits ``s`` on recorded frames it
held out of training: over all their pixels the least-squares ``s`` has the closed form
``<r - x, y - x> / |r - x|^2`` (``x`` the start, ``r`` the restored view, ``y`` the recorded
image), clipped to [0, 1] (never past the restorer's own step, never against it). The held-out
samples are built as training builds its degraded ones: the frame's warp filled by a cycle
reconstruction's render as the start, the renders at ``+-d`` as the two conditions.

A guided restorer's view may also keep the warp where the recorded frames saw the ground
(``SamplerConfig.keep_warp``). On a Cycles street the warp there is close to exact and the
restorer's output lost up to 9 dB to it; on a real stereo drive the warp carries one camera's
colours into another's and keeping it cost 0.1 dB. The fit scores both choices on the same
samples, each with its own least-squares share, and keeps the better one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from .config import SamplerConfig
from .data import PairSet
from .sampler import kept_warp, restore_image


@dataclass(frozen=True)
class StrengthFit:
    strength: float  # the fitted share, clipped to [0, 1]
    keep_warp: bool  # whether the view keeps the warp where frames saw the ground (the better choice)
    samples: int  # held-out (pair, degraded start) samples it was fitted on
    start_psnr: float  # the starts against the recorded images (dB, over all samples' pixels)
    restored_psnr: float  # the full correction (with the chosen keep_warp)
    fitted_psnr: float  # the fitted share (with the chosen keep_warp)
    other_psnr: float  # the fitted share of the other keep_warp choice (equal without a guide)

    def to_json(self) -> dict:
        return {k: round(v, 4) if isinstance(v, float) else v for k, v in vars(self).items()}


def held_out_samples(pairs: PairSet, guided: bool):
    """``(left, right, start, guide, target)`` [1, C, H, W] per held-out pair and degraded start."""
    for i in range(len(pairs)):
        for s in pairs.starts[i]:
            start, guide = pairs.filled_warp(i, s) if guided else (pairs.degraded[s], None)
            yield (pairs.left[i : i + 1], pairs.right[i : i + 1], start[None], None if guide is None else guide[None],
                   pairs.target[i : i + 1])


class _Sums:
    """What the least-squares share needs of one choice, summed over the samples."""

    def __init__(self):
        self.dot = self.norm = self.restored_se = 0.0

    def add(self, restored, start, target) -> None:
        step, error = restored - start, target - start
        self.dot += float((step * error).sum())
        self.norm += float((step * step).sum())
        self.restored_se += float(((restored - target) ** 2).sum())

    def share(self, start_se: float) -> tuple[float, float]:
        """The clipped least-squares share and its squared error."""
        s = 0.0 if self.norm == 0.0 else min(max(self.dot / self.norm, 0.0), 1.0)
        # |x + s (r - x) - y|^2 = |e|^2 - 2 s <step, e> + s^2 |step|^2, exactly: for s in [0, 1] the
        # view lies between two images in [0, 1], so the sampler's clamp changes nothing
        return s, start_se - 2.0 * s * self.dot + s * s * self.norm


def fit_strength(restorer, pairs: PairSet, sampler: SamplerConfig, *, guided: bool) -> StrengthFit | None:
    """The least-squares strength of ``restorer`` on ``pairs`` (held-out frames, with degraded
    starts; ``guided``: with warps) sampled by ``sampler``, and whether its views keep the warp;
    None where there is nothing to fit on."""
    full = replace(sampler, strength=1.0, keep_warp=False)
    sums = {True: _Sums(), False: _Sums()}
    start_se = 0.0
    pixels = samples = 0
    for left, right, start, guide, target in held_out_samples(pairs, guided):
        restored = restore_image(restorer, left, right, start, full, guide)
        kept = restored if guide is None else kept_warp(restored, guide)
        start, target = start.double(), target.double()
        sums[False].add(restored.double(), start, target)
        sums[True].add(kept.double(), start, target)
        start_se += float(((target - start) ** 2).sum())
        pixels, samples = pixels + target.numel(), samples + 1
    if not samples or sums[False].norm == 0.0:
        return None
    fits = {keep: sums[keep].share(start_se) for keep in (True, False)}
    keep = fits[True][1] <= fits[False][1]  # a tie (no guide, or nothing seen) keeps the warp

    def psnr(se: float) -> float:
        return 10.0 * math.log10(pixels / max(se, 1e-12))

    return StrengthFit(fits[keep][0], keep, samples, psnr(start_se), psnr(sums[keep].restored_se),
                       psnr(fits[keep][1]), psnr(fits[not keep][1]))
