"""Quality of a reconstruction against the package's Cycles ground truth.

``evaluate_heldout``: the training drive's held-out frames. ``evaluate_lateral``: the same
drive seen from cameras moved sideways (the degradation the restoration stage must fix), one
row per offset as ``report.json``'s ``metrics.lateral`` expects; the row helpers here are the
one lateral scorer, which the restoration's evaluation uses for its methods too.
PSNR in dB, SSIM (3DGS flavour) and, on lateral views, the colour-corrected ``psnr_cc``
(``symdrive_core.metrics``) on [0, 1] images, averaged over frames.
"""

from __future__ import annotations

import numpy as np
import torch

from ..gaussians import Gaussians
from ..io.images import read_image
from ..metrics import psnr, psnr_cc, ssim
from ..scene import Manifest
from ..scene.camera import CameraView
from ..scene.ground_truth import lateral_views, missing_truth, require_truth, split_frames
from ..splat.render import SplatRenderer, render_scene
from ..splat.tensors import GaussianTensors
from .lane_paint import lane_truth


def evaluate_heldout(manifest: Manifest, gaussians: Gaussians, frames: list[int] | None = None,
                     camera: str | None = None, actors: dict[str, Gaussians] | None = None,
                     shadows: dict | None = None, exposure: dict | None = None) -> dict:
    """{"psnr_heldout", "ssim_heldout", "frames"} over the held-out training-drive frames of
    ``camera``, else of every camera a reconstruction trains on (then also "cameras": the same
    per camera); with ``actors`` (a decomposed reconstruction's recorded vehicles, by actor id)
    they are rendered where the drive saw them, with their ``shadows`` (shadow layers, by actor id).
    A camera with a fitted colour transform (``exposure``, by camera name) is scored through it."""
    from ..optim.exposure import recorded_colours
    from ..optim.views import training_cameras

    frames = split_frames(manifest)[1] if frames is None else list(frames)
    if not frames:
        raise ValueError("evaluate_heldout: the package holds out no frames")
    cams = [manifest.camera(camera)] if camera else training_cameras(manifest)
    render, by_camera = recorded_renderer(manifest, gaussians, actors, shadows), {}
    for cam in cams:
        scores = []
        for i in frames:
            pred = recorded_colours(render(CameraView.of_frame(cam, i), i), (exposure or {}).get(cam.name))
            gt = read_image(manifest.resolve(cam.frames[i].image), channels=3)
            scores.append((psnr(pred, gt), ssim(pred, gt)))
        by_camera[cam.name] = scores
    p, s = np.mean([x for scores in by_camera.values() for x in scores], axis=0)
    out = {"psnr_heldout": round(float(p), 3), "ssim_heldout": round(float(s), 4), "frames": len(frames)}
    if len(cams) > 1:
        out["cameras"] = {name: {"psnr_heldout": round(float(np.mean([x[0] for x in v])), 3),
                                 "ssim_heldout": round(float(np.mean([x[1] for x in v])), 4)}
                          for name, v in by_camera.items()}
    return out


def recorded_renderer(manifest: Manifest, gaussians: Gaussians, actors: dict[str, Gaussians] | None,
                      shadows: dict | None = None):
    """``(view, frame) -> [H, W, 3]``: the background, plus ``actors`` at their recorded poses with
    their ``shadows`` (the parameters converted once, not per frame)."""
    if not actors:
        static = SplatRenderer(gaussians)
        return lambda view, frame: static(view)
    scene = TrafficRenderer(gaussians, actors, shadows)
    return lambda view, frame: scene.render(manifest, None, frame, view=view, recorded=True)[0]


class TrafficRenderer:
    """Background plus recorded vehicles (by actor id), each Gaussian set converted once; where the
    scene has a sun, each vehicle with a shadow layer (``shadows``, by actor id: what a decomposed
    fit learnt, :mod:`symdrive_core.optim.recorded_shadows`) lays it on the background."""

    def __init__(self, background: Gaussians, actors: dict[str, Gaussians], shadows: dict | None = None):
        self.background = GaussianTensors.from_gaussians(background)
        self.actors = {k: GaussianTensors.from_gaussians(g) for k, g in actors.items()}
        self.shadows = dict(shadows or {})

    @torch.no_grad()
    def render(self, manifest: Manifest, camera: str | None, frame: int, *, view: CameraView | None = None,
               recorded: bool = False):
        """(rgb [H, W, 3], actor id -> alpha [H, W]) of ``manifest``'s actors at ``frame``, seen by
        ``camera`` at that frame (or ``view``): as edited, or where the drive saw them (``recorded``)."""
        placed, ids, maps = [], {}, []
        for a in manifest.actors:
            pose = a.recorded_pose(frame) if recorded else a.pose(frame)
            if a.id in self.actors and pose is not None:
                placed.append((self.actors[a.id], pose, a.instance_id))
                ids[a.instance_id] = a.id
                if a.id in self.shadows and a.wlh is not None:
                    maps.append(self.shadows[a.id].at(pose, a.wlh))
        view = view or CameraView.of_frame(manifest.camera(camera), frame)
        out = render_scene(self.background, placed, view)
        alphas = {ids[iid]: out["instance"][..., k].numpy() for k, iid in enumerate(out["actor_ids"])}
        rgb = out["rgb"].clamp(0, 1).numpy()
        if maps and manifest.effects.casting_sun()[0] is not None:
            from ..shadows.cast import lay_shadows

            street = render_scene(self.background, [], view)
            rgb, _ = lay_shadows(rgb, alphas.values(), street["rgb"].clamp(0, 1).numpy(),
                                 street["depth"][..., 0].numpy(), maps, view.camera_to_world, view.K,
                                 manifest.effects.shade)
        return rgb, alphas

    @torch.no_grad()
    def street_depth(self, manifest: Manifest, camera: str, frame: int) -> np.ndarray:
        """The background's camera z at ``frame`` (0 where nothing is rendered)."""
        return render_scene(self.background, [], CameraView.of_frame(manifest.camera(camera), frame))["depth"][
            ..., 0].numpy()


def lateral_targets(manifest: Manifest, frames: list[int] | None, needed_by: str | None = None) -> list:
    """The package's lateral ground-truth views (of ``frames``, or all), in offset then frame order;
    a :class:`ManifestError` on ``ground_truth.lateral`` when there are none to score against
    (``needed_by``: which option asked, for the message)."""
    require_truth(manifest, "lateral", needed_by)
    targets = [v for v in lateral_views(manifest) if frames is None or v.frame in frames]
    if not targets:
        which = "any frame" if frames is None else "frame(s) " + ", ".join(map(str, frames[:5])) + (
            ", ..." if len(frames) > 5 else "")
        raise missing_truth(manifest, "lateral", f"no lateral ground truth for {which}", needed_by)
    return targets


def lane_truths(manifest: Manifest, targets: list) -> dict:
    """(offset, frame) -> lane truth of every target view that has a lane mask, all read before
    any view is rendered or restored (a missing mask stops the run before its work)."""
    return {(v.offset_m, v.frame): lane_truth(manifest, v.lanes, v.K, v.camera_to_world)
            for v in targets if v.lanes is not None}


def with_ceiling(lanes, gt: np.ndarray, offset: float, ceilings: dict[float, list[float]]):
    """``lanes`` (None passes through), after recording the segmenter's IoU on the Cycles
    image itself: the ceiling at ``offset``."""
    if lanes is not None:
        ceilings.setdefault(offset, []).append(lanes.iou(gt))
    return lanes


def score_view(img: np.ndarray, gt: np.ndarray, lanes) -> dict[str, float]:
    """``psnr``, ``ssim`` and ``psnr_cc`` against the truth image, and ``lane_iou`` (0 to 1) where
    the view has a lane mask. Every method's view, the raw render's included, goes through this
    one scorer, so each gets the same colour fit."""
    scores = {"psnr": psnr(img, gt), "ssim": ssim(img, gt), "psnr_cc": psnr_cc(img, gt)}
    if lanes is not None:
        scores["lane_iou"] = lanes.iou(img)
    return scores


def lateral_rows(scores: dict[tuple[float, str], list[dict]], seconds: dict[str, float],
          ceilings: dict[float, list[float]]) -> list[dict]:
    """One row per (offset, method) from :func:`score_view`'s scores: ``psnr``, ``ssim``,
    ``psnr_cc`` and, where every view has a lane mask, ``lane_iou`` and its ceiling
    ``lane_iou_ceiling`` in IoU points (0 to 100)."""
    rows = []
    for (off, method), vals in sorted(scores.items(), key=lambda kv: (abs(kv[0][0]), kv[0][0], kv[0][1])):
        row = {
            "offset_m": off,
            "method": method,
            "psnr": round(float(np.mean([v["psnr"] for v in vals])), 3),
            "ssim": round(float(np.mean([v["ssim"] for v in vals])), 4),
            "psnr_cc": round(float(np.mean([v["psnr_cc"] for v in vals])), 3),
            "frames": len(vals),
        }
        if all("lane_iou" in v for v in vals):
            row["lane_iou"] = round(100.0 * float(np.mean([v["lane_iou"] for v in vals])), 2)
            row["lane_iou_ceiling"] = round(100.0 * float(np.mean(ceilings[off])), 2)
        if method in seconds:
            row["seconds_per_view"] = round(seconds[method], 3)
        rows.append(row)
    return rows


def evaluate_lateral(manifest: Manifest, gaussians: Gaussians, method: str = "raw_3dgs",
                     frames: list[int] | None = None, *, render: SplatRenderer | None = None) -> list[dict]:
    """Rows for a reconstruction rendered as is (``raw_3dgs``, ``refined``) on the same views
    (``render``: a renderer of ``gaussians`` the caller already holds)."""
    render = render or SplatRenderer(gaussians)
    scores: dict[tuple[float, str], list] = {}
    ceilings: dict[float, list[float]] = {}
    targets = lateral_targets(manifest, frames)
    truths = lane_truths(manifest, targets)
    for v in targets:
        img = render(v.camera)
        gt = read_image(manifest.resolve(v.image), channels=3)
        lanes = with_ceiling(truths.get((v.offset_m, v.frame)), gt, v.offset_m, ceilings)
        scores.setdefault((v.offset_m, method), []).append(score_view(img, gt, lanes))
    return lateral_rows(scores, {}, ceilings)
