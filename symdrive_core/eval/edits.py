"""Moving traffic against its Cycles truth: a decomposed reconstruction's held-out frames (over
the image and over the moving vehicles' pixels), and edits of recorded vehicles (remove, move,
retime) rendered with and without inpainting of what they expose.

Scores are PSNR in dB over masks (:func:`symdrive_core.metrics.psnr` on the masked pixels). The
package's ``ground_truth.vehicles`` and ``ground_truth.edits`` hold the truth
(:mod:`symdrive_core.scene.ground_truth`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from ..gaussians import Gaussians
from ..insertion.exposed import VEHICLE_ALPHA, exposed_region, inpaint_region
from ..io.images import read_image, read_mask
from ..metrics import psnr
from ..scene import Manifest
from ..scene.camera import CameraView
from ..scene.ground_truth import EditTruth, edit_truth, require_truth, split_frames, vehicle_masks
from .views import TrafficRenderer

Inpainter = Callable[[np.ndarray, np.ndarray], np.ndarray]


def _masked(pred: np.ndarray, truth: np.ndarray, mask: np.ndarray) -> float | None:
    return float(psnr(pred[mask], truth[mask])) if mask.any() else None


def _mean(values) -> float | None:
    values = [v for v in values if v is not None]
    return round(float(np.mean(values)), 3) if values else None


def evaluate_decomposition(manifest: Manifest, background: Gaussians, actors: dict[str, Gaussians],
                           frames: list[int] | None = None, shadows: dict | None = None,
                           masks: dict[int, np.ndarray] | None = None, camera: str | None = None) -> dict:
    """Held-out frames of ``camera`` (the package's first by default): PSNR over the image, over the
    moving vehicles' pixels and elsewhere (the truth's vehicle masks, or ``masks``: boolean images
    by frame, where a real drive's labels put its moving vehicles), the recorded vehicles at their
    recorded poses with their ``shadows`` (shadow layers, by actor id)."""
    frames = split_frames(manifest)[1] if frames is None else frames
    cam = manifest.camera(camera) if camera else manifest.cameras[0]
    if masks is None:
        if cam is not manifest.cameras[0]:
            raise ValueError(f"the truth's vehicle masks are camera {manifest.cameras[0].name}'s: pass {cam.name}'s")
        require_truth(manifest, "vehicles", "scoring moving vehicles needs their masks")
        paths = vehicle_masks(manifest)
        masks = {f: read_mask(manifest.resolve(paths[f])) > 0.5 for f in frames if f in paths}
    frames = [f for f in frames if f in masks]
    renderer = TrafficRenderer(background, actors, shadows)
    rows = {"image": [], "vehicles": [], "elsewhere": []}
    for f in frames:
        rgb, _ = renderer.render(manifest, cam.name, f, recorded=True)
        truth = read_image(manifest.resolve(cam.frames[f].image), channels=3)
        vehicles = masks[f]
        rows["image"].append(float(psnr(rgb, truth)))
        rows["vehicles"].append(_masked(rgb, truth, vehicles))
        rows["elsewhere"].append(_masked(rgb, truth, ~vehicles))
    return {"frames": len(frames), **{f"psnr_{k}": _mean(v) for k, v in rows.items()}}


SHADOW_TRUTH_STEP = 0.04  # sRGB change (any channel) above Cycles' residual noise: the removed car's doing


def removed_shadow(recorded: np.ndarray, without: np.ndarray, car: np.ndarray) -> np.ndarray:
    """The pixels outside a removed car's mask that its removal changes in the truth (the recorded
    frame against Cycles' render without the car) by more than :data:`SHADOW_TRUTH_STEP`: its
    shadow, and the little light it threw on what stands near."""
    step = np.abs(np.asarray(recorded, np.float64) - np.asarray(without, np.float64)).max(-1)
    return (step > SHADOW_TRUTH_STEP) & ~car


def edited(manifest: Manifest, edit: EditTruth) -> Manifest:
    """``manifest`` with ``edit`` applied at its frame: the actor removed there (remove) or at the
    truth's edited pose (move, retime), its recorded poses kept."""
    actors = []
    for a in manifest.actors:
        if a.id == edit.actor:
            poses = list(a.poses)
            poses[edit.frame] = edit.pose
            a = replace(a, poses=poses, recorded_poses=list(a.recorded_poses or a.poses))
        actors.append(a)
    return replace(manifest, actors=actors)


def evaluate_edits(manifest: Manifest, background: Gaussians, actors: dict[str, Gaussians],
                   inpaint: Inpainter | None = None, dilate_px: int = 2, shadows: dict | None = None) -> dict:
    """Per edit kind, the edited frame against Cycles' (``ground_truth.edits``): PSNR over the
    region the edit exposes (remove: the car's recorded pixels, and those with its shadow,
    :func:`removed_shadow`; move, retime: where it was and no vehicle is now) and, for move and
    retime, over the car where the truth shows it now; as
    rendered ("dropped": the car's Gaussians moved or gone) and, with ``inpaint``, with the exposed
    region inpainted. The vehicles lay their ``shadows`` (shadow layers, by actor id) where
    they are."""
    require_truth(manifest, "edits", "scoring edits needs their Cycles renders")
    renderer = TrafficRenderer(background, actors, shadows)
    rows: dict[str, dict[str, list]] = {}
    for e in edit_truth(manifest):
        m = edited(manifest, e)
        _, recorded = renderer.render(m, e.camera, e.frame, recorded=True)
        rgb, now = renderer.render(m, e.camera, e.frame)
        region = exposed_region(recorded, now, [e.actor], dilate_px)
        region = np.zeros(rgb.shape[:2], bool) if region is None else region
        hole = inpaint_region(m, CameraView.of_frame(m.camera(e.camera), e.frame), recorded, now, [e.actor],
                              renderer.street_depth(m, e.camera, e.frame), dilate_px)
        truth = read_image(manifest.resolve(e.image), channels=3)
        car = read_mask(manifest.resolve(e.mask)) > 0.5
        row = rows.setdefault(e.kind, {})
        score_region = car if e.kind == "remove" else region & ~car
        row.setdefault("exposed_dropped", []).append(_masked(rgb, truth, score_region))
        row.setdefault("unseen_fraction", []).append(
            float((hole & score_region).sum() / max(score_region.sum(), 1)) if hole is not None else 0.0)
        if inpaint is not None:
            filled = inpaint(rgb, hole) if hole is not None else rgb
            row.setdefault("exposed_inpainted", []).append(_masked(filled, truth, score_region))
        if e.kind == "remove":
            recorded_truth = read_image(manifest.resolve(manifest.camera(e.camera).frames[e.frame].image), channels=3)
            with_shadow = car | removed_shadow(recorded_truth, truth, car)
            row.setdefault("car_and_shadow_dropped", []).append(_masked(rgb, truth, with_shadow))
            if inpaint is not None:
                row.setdefault("car_and_shadow_inpainted", []).append(_masked(filled, truth, with_shadow))
        else:
            row.setdefault("car", []).append(_masked(rgb, truth, car))
            row.setdefault("car_silhouette_iou", []).append(_iou(now.get(e.actor), car))
    return {kind: {"edits": len(next(iter(r.values()))),
                   **{k if k in UNSCALED else f"psnr_{k}": _mean(v) for k, v in r.items()}} for kind, r in rows.items()}


UNSCALED = {"car_silhouette_iou", "unseen_fraction"}


def _iou(alpha: np.ndarray | None, truth: np.ndarray) -> float | None:
    if alpha is None or not truth.any():
        return None
    mine = alpha >= VEHICLE_ALPHA
    return float((mine & truth).sum() / (mine | truth).sum())
