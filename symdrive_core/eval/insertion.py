"""Insertion quality on held-out placements, against Cycles renders of the vehicle truly in the scene.

Per placement: the studio-lit asset is inserted naively, colour-transferred (Reinhard), given
its cast shadow (scenes with a sun), harmonized (RePaint with the restorer, on the insertion
with its shadow), and fine-tuned (colour/opacity only, on harmonized *training* views of the
same parked vehicle; the held-out view is never seen), then rendered as is and with its
shadow. Masked metrics use the true vehicle mask ∪ its true shadow, the region where the real
image differs from the empty scene; full-image PSNR also counts the background
reconstruction's own error.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from ..insertion.assets import load_vehicle_asset
from ..insertion.baselines import naive, reinhard_transfer
from ..insertion.features import crop_frechet, vehicle_crop
from ..insertion.harmonizer import Harmonizer, restorer_harmonizer
from ..insertion.insert import InsertionConfig, finetune_sample, insert_frame
from ..insertion.placements import HeldOut, camera_view, held_out_placements, training_views
from ..io.images import read_image, read_mask
from ..io.ply import write_splats
from ..metrics import psnr, ssim
from ..optim.finetune import finetune_colors
from ..scene import Manifest
from ..scene.ground_truth import require_truth, split_frames
from ..shadows.cast import vehicle_shadow

METHODS = ("naive", "color_transfer", "cast_shadow", "harmonized", "finetuned", "finetuned_shadow")


def truth(manifest: Manifest, placement: HeldOut) -> tuple[np.ndarray, np.ndarray]:
    """The Cycles image of the car truly in the scene, and the scored mask (car ∪ its shadow)."""
    gt = read_image(manifest.resolve(placement.with_image), channels=3)
    mask = read_mask(manifest.resolve(placement.mask)) > 0.5
    if placement.shadow_mask:
        mask |= read_mask(manifest.resolve(placement.shadow_mask)) > 0.5
    return gt, mask


def scores(pred, gt, mask) -> dict:
    return {"masked_psnr": psnr(pred, gt, mask), "masked_ssim": ssim(pred, gt, mask), "psnr": psnr(pred, gt)}


def evaluate_placement(manifest: Manifest, background, placement: HeldOut, harmonizer: Harmonizer | None,
                       cfg: InsertionConfig, timings: dict, progress: bool = False) -> dict:
    """Per-method scores and crops for one held-out placement."""
    asset = load_vehicle_asset(manifest.resolve(placement.asset))
    vehicle = asset.gaussians
    held = insert_frame(manifest, background, vehicle, placement.pose, placement.wlh, placement.camera,
                        cfg.shadow_dilate_px)
    images = {"naive": naive(held.plain), "color_transfer": reinhard_transfer(held.plain, held.vehicle_alpha)}
    if held.shadow is not None:
        images["cast_shadow"] = held.image
    if harmonizer is not None:
        t = time.perf_counter()
        images["harmonized"] = harmonizer(held.image, held.region)
        timings.setdefault("harmonize_seconds", []).append(time.perf_counter() - t)
        samples = []
        for fi in training_views(manifest, placement, split_frames(manifest)[0], cfg.train_views):
            frame = insert_frame(manifest, background, vehicle, placement.pose, placement.wlh,
                                 camera_view(manifest, fi, placement.camera_name), cfg.shadow_dilate_px)
            t = time.perf_counter()
            target = harmonizer(frame.image, frame.region)
            timings.setdefault("harmonize_seconds", []).append(time.perf_counter() - t)
            samples.append(finetune_sample(frame, target, background, vehicle, cfg))
        if samples:
            res = finetune_colors(vehicle, samples, cfg.finetune, progress=progress)
            timings.setdefault("finetune_seconds", []).append(res.seconds)
            timings.setdefault("finetune_views", []).append(len(samples))
            rgb, alpha = held.view.render_numpy(res.gaussians)
            images["finetuned"] = rgb
            if held.shadow is not None:  # the shadow of the fine-tuned opacities
                cast = vehicle_shadow(held.view, res.gaussians, placement.pose, placement.wlh,
                                      manifest.effects.sun_direction, held.shadow.ratio)
                images["finetuned_shadow"] = cast.apply(rgb, alpha)
            if cfg.assets_out is not None:
                write_splats(Path(cfg.assets_out) / f"{placement.index:02d}_{asset.name}.ply", res.gaussians)
    gt, mask = truth(manifest, placement)
    return {"scores": {m: scores(img, gt, mask) for m, img in images.items()},
            "crops": {m: vehicle_crop(img, mask) for m, img in images.items()} | {"real": vehicle_crop(gt, mask)}}


def evaluate_insertion(manifest: Manifest, background_gaussians, restorer=None, *, harmonizer: Harmonizer | None = None,
                       config: InsertionConfig | None = None, extractor=None, details: dict | None = None,
                       progress: bool = True, frames: list[int] | None = None) -> list[dict]:
    """Rows ``{"method", "masked_psnr", "masked_ssim", "psnr"[, "frechet"]}`` averaged over the
    package's held-out placements (report.json's ``metrics.insertion``), those at ``frames`` where
    given (a run's frame window; none there: no rows).

    ``restorer`` is the diffusion model (or pass a ready ``harmonizer``); without either only the
    naive and colour-transfer rows are measured. ``extractor`` adds a Frechet distance between
    real and inserted vehicle crops. ``details`` (a dict) receives per-placement scores and timings.
    A package without ``ground_truth.insertion`` has nothing to score: a :class:`ManifestError`.
    """
    from ..splat.tensors import GaussianTensors

    cfg = config or InsertionConfig()
    if harmonizer is None and restorer is not None:
        harmonizer = restorer_harmonizer(restorer)
    background = None if background_gaussians is None else (
        background_gaussians if isinstance(background_gaussians, GaussianTensors)
        else GaussianTensors.from_gaussians(background_gaussians))
    require_truth(manifest, "insertion")
    placements = [p for p in held_out_placements(manifest) if frames is None or p.frame in frames]
    timings: dict = {}
    results = [evaluate_placement(manifest, background, p, harmonizer, cfg, timings, progress)
               for p in tqdm(placements, desc="insertion", unit="placement", disable=not progress)]
    rows = []
    for method in METHODS:
        per = [r["scores"][method] for r in results if method in r["scores"]]
        if not per:
            continue
        row = {"method": method, **{k: round(float(np.mean([s[k] for s in per])), 4) for k in per[0]},
               "placements": len(per)}
        if extractor is not None and len(per) >= 2:
            row["frechet"] = round(crop_frechet(extractor, [r["crops"]["real"] for r in results],
                                                [r["crops"][method] for r in results]), 4)
        rows.append(row)
    if details is not None:
        details["placements"] = [r["scores"] for r in results]
        details["timings"] = {k: [round(v, 3) for v in vals] for k, vals in timings.items()}
    return rows
