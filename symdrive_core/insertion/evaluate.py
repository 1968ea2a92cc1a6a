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
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from tqdm import tqdm

from ..gaussians import Gaussians
from ..io.images import read_image, read_mask
from ..io.ply import write_splats
from ..metrics import bbox_crop, psnr, ssim
from ..optim.finetune import FinetuneConfig, FinetuneSample, finetune_colors
from ..scene import Manifest, Pose
from ..scene.camera import CameraView
from ..scene.ground_truth import split_frames
from ..splat.frozen_view import FrozenView
from .assets import load_vehicle_asset
from .baselines import naive, reinhard_transfer
from .cast_shadow import CastShadow, vehicle_shadow
from .composite import insertion_view
from .features import crop_frechet, vehicle_crop
from .harmonizer import Harmonizer, restorer_harmonizer
from .placements import HeldOut, camera_view, held_out_placements, training_views
from .shadow import dilate, harmonization_region, shadow_region

METHODS = ("naive", "color_transfer", "cast_shadow", "harmonized", "finetuned", "finetuned_shadow")


@dataclass
class InsertionConfig:
    train_views: int = 6
    crop_margin: int = 6  # pixels around the harmonized region kept for the fine-tune
    loss_ring_px: int = 2  # the fine-tune looks at the vehicle plus this ring (keeps opacity honest)
    shadow_dilate_px: int = 3
    finetune: FinetuneConfig = field(default_factory=FinetuneConfig)
    assets_out: Path | None = None  # write each fine-tuned asset here as a splat PLY


@dataclass
class InsertedFrame:
    image: np.ndarray  # the insertion as the scene calls for it: ``plain`` plus its cast shadow under a sun
    plain: np.ndarray  # the naive render [H, W, 3]
    vehicle_alpha: np.ndarray  # [H, W]
    region: np.ndarray  # [H, W] bool: vehicle ∪ shadow region (what harmonization may change)
    view: FrozenView
    pose: Pose  # the vehicle's
    shadow: CastShadow | None = None  # None: no sun, or shadows off


def insert_frame(manifest: Manifest, background, vehicle: Gaussians, pose, wlh, camera: CameraView,
                 shadow_px: int = 3) -> InsertedFrame:
    """Render one insertion (with the shadow it casts where the scene has a sun) and the region
    harmonization may change."""
    view = insertion_view(camera, background, vehicle, pose)
    rgb, alpha = view.render_numpy(vehicle)
    eff = manifest.effects
    region, cast = None, None
    if eff.shadows and eff.sun_direction is not None:
        region = shadow_region(pose, wlh, eff.sun_direction, camera.camera_to_world, camera.K, camera.width,
                               camera.height, dilate_px=shadow_px)
        cast = vehicle_shadow(view, vehicle, pose, wlh, eff.sun_direction, eff.shade)
    image = rgb if cast is None else cast.apply(rgb, alpha)
    return InsertedFrame(image, rgb, alpha, harmonization_region(alpha, region), view, pose, cast)


def finetune_sample(frame: InsertedFrame, target: np.ndarray, background, vehicle: Gaussians,
                    cfg: InsertionConfig) -> FinetuneSample:
    """The harmonized frame's window around the region, projected once for the fine-tune. The
    loss looks at the vehicle and a thin ring of background, minus the ring's shadowed pixels
    (the fine-tune renders no shadow, and must not grow the car to imitate one)."""
    rows, cols = bbox_crop(frame.region, cfg.crop_margin)
    view = insertion_view(frame.view.camera.crop(rows, cols), background, vehicle, frame.pose)
    on_car = frame.vehicle_alpha > 0.01
    mask = dilate(on_car, cfg.loss_ring_px)
    if frame.shadow is not None:
        mask &= on_car | (frame.shadow.occlusion <= 0.01)
    mask = mask[rows, cols].astype(np.float32)
    return FinetuneSample(view, np.ascontiguousarray(target[rows, cols]), mask)


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
                       progress: bool = True) -> list[dict]:
    """Rows ``{"method", "masked_psnr", "masked_ssim", "psnr"[, "frechet"]}`` averaged over the
    package's held-out placements (REPORT.md's ``metrics.insertion``).

    ``restorer`` is the diffusion model (or pass a ready ``harmonizer``); without either only the
    naive and colour-transfer rows are measured. ``extractor`` adds a Frechet distance between
    real and inserted vehicle crops. ``details`` (a dict) receives per-placement scores and timings.
    """
    from ..splat.tensors import GaussianTensors

    cfg = config or InsertionConfig()
    if harmonizer is None and restorer is not None:
        harmonizer = restorer_harmonizer(restorer)
    background = None if background_gaussians is None else (
        background_gaussians if isinstance(background_gaussians, GaussianTensors)
        else GaussianTensors.from_gaussians(background_gaussians))
    placements = held_out_placements(manifest)
    if not placements:
        return []
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
