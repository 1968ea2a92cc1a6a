"""The restoration study: every lateral ground-truth view restored by each method and scored
against the truth (``metrics.lateral``), and the refinement on restored views next to its control.
The chain itself is :mod:`symdrive_core.diffusion.restore`."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..diffusion.restore import WARP, LateralChain, RestoredView, chain_warper, method_step, needs_warp
from ..diffusion.sampler import DEFAULT, SamplerConfig
from ..gaussians import Gaussians
from ..io.images import read_image
from ..scene import Manifest
from ..scene.ground_truth import truth_camera
from ..splat.render import SplatRenderer
from .views import lane_truths, lateral_rows, lateral_targets, score_view, with_ceiling


@dataclass
class LateralRestoration:
    rows: list[dict]
    views: dict[str, list[RestoredView]] = field(default_factory=dict)
    chains: dict[int, LateralChain] = field(default_factory=dict)  # by frame, their restorations cached
    ground: dict | None = None  # the warp's ground planes and what each was fitted to (guided methods)



def run_lateral_restoration(
    manifest: Manifest,
    gaussians: Gaussians,
    restorer,
    *,
    methods=("single_view", "ar_d0.5", "ar_d1.0"),
    sampler: SamplerConfig = DEFAULT,
    frames: list[int] | None = None,
    progress: bool = True,
    warper=None,
    render: SplatRenderer | None = None,
) -> LateralRestoration:
    """Restore every lateral ground-truth view of the package (or of ``frames``) with each
    method, score it against the Cycles image, and keep the restored views. ``warper``: the
    lateral camera's, for the geometry-guided methods (default: fitted here when they are asked for);
    ``render``: a renderer of ``gaussians`` the caller already holds."""
    from tqdm import tqdm

    targets = lateral_targets(manifest, frames)
    truths = lane_truths(manifest, targets)
    for m in methods:
        if m != WARP:
            method_step(m)  # an unknown name fails before any work
    render = render or SplatRenderer(gaussians)
    cam = truth_camera(manifest)
    if warper is None and needs_warp(methods):
        warper = chain_warper(manifest, cam, gaussians)
    scores: dict[tuple[float, str], list] = {}
    ceilings: dict[float, list[float]] = {}
    seconds: dict[str, list[float]] = {}
    result = LateralRestoration(rows=[], ground=None if warper is None else warper.ground.summary())
    by_frame: dict[int, list] = {}
    for v in targets:
        by_frame.setdefault(v.frame, []).append(v)
    bar = tqdm(total=len(targets) * len(methods), desc="restore", unit="view", disable=not progress)
    for fi, views in sorted(by_frame.items()):
        chain = result.chains[fi] = LateralChain.for_frame(manifest, cam, fi, restorer, render, sampler, warper)
        for v in sorted(views, key=lambda v: abs(v.offset_m)):
            gt = read_image(manifest.resolve(v.image), channels=3)
            lanes = with_ceiling(truths.get((v.offset_m, v.frame)), gt, v.offset_m, ceilings)
            for method in methods:
                before, t0 = chain.samples, time.perf_counter()
                img = chain.by_method(v.offset_m, method)
                if chain.samples > before:
                    seconds.setdefault(method, []).append(
                        (time.perf_counter() - t0) / (chain.samples - before)
                    )

                scores.setdefault((v.offset_m, method), []).append(score_view(img, gt, lanes))
                result.views.setdefault(method, []).append(
                    RestoredView(fi, v.offset_m, v.camera, img)
                )
                bar.update()
    bar.close()
    warp_seconds = [t for c in result.chains.values() for t in c.warp_seconds]
    if WARP in methods and warp_seconds:  # the render at the shifted camera included
        seconds[WARP] = warp_seconds
    result.rows = lateral_rows(scores, {m: float(np.mean(s)) for m, s in seconds.items()}, ceilings)
    return result


def evaluate_lateral_restoration(manifest: Manifest, gaussians: Gaussians, model, **options) -> list[dict]:
    """``metrics.lateral`` rows (``{"offset_m", "method", "psnr", "ssim", "psnr_cc", ...}``) for each method;
    options as :func:`run_lateral_restoration`."""
    return run_lateral_restoration(manifest, gaussians, model, **options).rows


@dataclass
class RefineStudy:
    """What ``restore --evaluate --refine`` refines on: the views at ``+-offsets`` of ``frames``
    (None: every recorded frame), restored by the chain with ``step``, ``iters`` iterations."""

    offsets: list[float]
    step: float
    frames: list[int] | None
    iters: int
    guided: bool = False


def restoration_study(manifest: Manifest, gaussians: Gaussians, restorer, *, methods, sampler: SamplerConfig,
                      frames: list[int] | None = None, refine: RefineStudy | None = None,
                      progress: bool = True) -> tuple[dict, Gaussians | None]:
    """Raw 3DGS and each of ``methods`` against the lateral truth (``metrics["lateral"]``); with
    ``refine``, the reconstruction refined on restored views next to its control (the same
    refinement on the recorded views alone, so the table shows what the restored views add beyond
    training longer). Returns the metrics and the refined Gaussians (None without ``refine``)."""
    from ..diffusion.refine import RefineConfig, refine_gaussians
    from ..diffusion.restore import restore_lateral_views
    from .views import evaluate_lateral

    t0 = time.perf_counter()
    result = run_lateral_restoration(manifest, gaussians, restorer, methods=methods, sampler=sampler, frames=frames,
                                     progress=progress)
    rows = evaluate_lateral(manifest, gaussians, "raw_3dgs", frames) + result.rows
    metrics = {"sampler": vars(sampler), "seconds": round(time.perf_counter() - t0, 1), "lateral": rows,
               **({"ground": result.ground} if result.ground else {})}
    if refine is None:
        return metrics, None
    # As the pipeline does: the lateral views of every recorded frame (not only the scored ones),
    # restored by the chain; the scored chains are reused.
    t0 = time.perf_counter()
    views = restore_lateral_views(manifest, gaussians, restorer, refine.frames, refine.offsets, refine.step,
                                  sampler=sampler, chains=result.chains, progress=progress, guided=refine.guided)
    restore_seconds = round(time.perf_counter() - t0, 1)
    cfg = RefineConfig(iters=refine.iters)
    refined, stats = refine_gaussians(manifest, gaussians, views, cfg, progress=progress)
    control, control_stats = refine_gaussians(manifest, gaussians, [], cfg, progress=progress)
    metrics["refine"] = {**stats, "step_m": refine.step, "frames": sorted({v.frame for v in views}),
                         "offsets_m": list(refine.offsets), "restore_seconds": restore_seconds,
                         "control_seconds": control_stats["seconds"]}
    metrics["lateral"] += evaluate_lateral(manifest, refined, "refined", frames)
    metrics["lateral"] += evaluate_lateral(manifest, control, "refined_recorded_only", frames)
    return metrics, refined
