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
(``SamplerConfig.keep_warp``). Whether it should is a question about lateral views, which the
frames held out at the recorded camera do not answer: there the adapted restorer is on the views
it trained for, and on a Cycles street it never saw they preferred its output (31.27 against
30.95 dB), while at 1 m sideways keeping the warp scored 2.2 dB higher. So the choice is made
only on held-out pairs whose target a rig's second camera recorded (lateral truth), each choice
with its own least-squares share; without such pairs the warp is kept. On two real KITTI stereo
drives they chose not to keep it, which their right cameras' held-out views confirmed (0.1 dB).
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
    keep_warp: bool  # whether the view keeps the warp where frames saw the ground
    samples: int  # held-out (pair, degraded start) samples it was fitted on
    start_psnr: float  # the starts against the recorded images (dB, over all samples' pixels)
    restored_psnr: float  # the full correction (with the chosen keep_warp)
    fitted_psnr: float  # the fitted share (with the chosen keep_warp)
    lateral_samples: int  # those whose target a second camera recorded: what keep_warp was chosen on
    kept_psnr: float | None  # on them, each choice at its own fitted share (None: no such samples)
    free_psnr: float | None

    def to_json(self) -> dict:
        return {k: round(v, 4) if isinstance(v, float) else v for k, v in vars(self).items()}


def held_out_samples(pairs: PairSet, guided: bool):
    """``(left, right, start, guide, target, lateral)`` per held-out pair and degraded start, the
    images [1, C, H, W]; ``lateral``: a rig's second camera recorded the target."""
    for i in range(len(pairs)):
        for s in pairs.starts[i]:
            start, guide = pairs.filled_warp(i, s) if guided else (pairs.degraded[s], None)
            yield (pairs.left[i : i + 1], pairs.right[i : i + 1], start[None], None if guide is None else guide[None],
                   pairs.target[i : i + 1], bool(pairs.from_sensor[i]))


class _Sums:
    """What the least-squares share needs of one way of making the view, summed over samples."""

    def __init__(self):
        self.dot = self.norm = self.start_se = self.restored_se = 0.0
        self.pixels = 0

    def add(self, restored, start, target) -> None:
        step, error = restored - start, target - start
        self.dot += float((step * error).sum())
        self.norm += float((step * step).sum())
        self.start_se += float((error * error).sum())
        self.restored_se += float(((restored - target) ** 2).sum())
        self.pixels += target.numel()

    def share(self) -> float:
        """The least-squares share, clipped to [0, 1] (never past the step, never against it)."""
        return 0.0 if self.norm == 0.0 else min(max(self.dot / self.norm, 0.0), 1.0)

    def psnr(self, s: float) -> float:
        """PSNR of the views at share ``s``: |x + s (r - x) - y|^2 = |e|^2 - 2 s <step, e> +
        s^2 |step|^2, exactly (for s in [0, 1] the view lies between two images in [0, 1], so the
        sampler's clamp changes nothing)."""
        return _psnr(self.pixels, self.start_se - 2.0 * s * self.dot + s * s * self.norm)


def _psnr(pixels: int, se: float) -> float:
    return 10.0 * math.log10(pixels / max(se, 1e-12))


def fit_strength(restorer, pairs: PairSet, sampler: SamplerConfig, *, guided: bool) -> StrengthFit | None:
    """The least-squares strength of ``restorer`` on ``pairs`` (held-out frames, with degraded
    starts; ``guided``: with warps) sampled by ``sampler``, and whether its views keep the warp;
    None where there is nothing to fit on."""
    full = replace(sampler, strength=1.0, keep_warp=False)
    every = {True: _Sums(), False: _Sums()}  # by keep_warp: all samples, and the lateral ones
    lateral = {True: _Sums(), False: _Sums()}
    samples = lateral_samples = 0
    for left, right, start, guide, target, from_rig in held_out_samples(pairs, guided):
        samples, lateral_samples = samples + 1, lateral_samples + from_rig
        restored = restore_image(restorer, left, right, start, full, guide)
        views = {False: restored, True: restored if guide is None else kept_warp(restored, guide)}
        x, y = start.double(), target.double()
        for keep, view in views.items():
            r = view.double()
            for sums in (every, lateral) if from_rig else (every,):
                sums[keep].add(r, x, y)
    if not every[False].pixels or every[False].norm == 0.0:
        return None
    seen = lateral[True].pixels > 0
    kept, free = (lateral[k].psnr(lateral[k].share()) for k in (True, False)) if seen else (None, None)
    keep = not seen or kept >= free
    chosen = every[keep]
    s = chosen.share()
    return StrengthFit(s, keep, samples, _psnr(chosen.pixels, chosen.start_se), _psnr(chosen.pixels, chosen.restored_se),
                       chosen.psnr(s), lateral_samples, kept, free)
