"""Inserting a vehicle into a view: the production path of the harmonize and fine-tune stages.

The vehicle is placed in the world (:func:`~.place.place`) and seen through a frozen view
(:mod:`symdrive_core.splat.frozen_view`: projected once, its SH evaluated in its own frame); where
the scene has a sun it casts its shadow (:mod:`symdrive_core.shadows.cast`), and the region harmonization may
change is the vehicle plus that shadow. :mod:`.evaluate` scores what this produces.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..gaussians import Gaussians
from ..metrics import bbox_crop
from ..optim.finetune import FinetuneSample
from ..scene import Manifest, Pose
from ..scene.camera import CameraView
from ..scene.place import place
from ..shadows.cast import CastShadow, vehicle_shadow
from ..shadows.region import dilate, harmonization_region, shadow_region
from ..splat.frozen_view import FrozenView
from ..splat.tensors import GaussianTensors
from .config import InsertionConfig


def insertion_view(camera: CameraView, background: GaussianTensors | None, vehicle: Gaussians, pose: Pose,
                   *, background_color=(0.0, 0.0, 0.0)) -> FrozenView:
    """``camera``'s view of ``background`` with ``vehicle`` at ``pose``, projected once."""
    return FrozenView(camera, background, place(vehicle, pose), pose.R, background_color=background_color)


def render_insertion(camera: CameraView, background: GaussianTensors | None, vehicle: Gaussians, pose: Pose,
                     *, background_color=(0.0, 0.0, 0.0)):
    """Naive insertion of one vehicle: (rgb [H,W,3], vehicle alpha [H,W]) as numpy."""
    return insertion_view(camera, background, vehicle, pose, background_color=background_color).render_numpy(vehicle)


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
    sun, _ = manifest.effects.casting_sun()
    region, cast = None, None
    if sun is not None:
        region = shadow_region(pose, wlh, sun, camera.camera_to_world, camera.K, camera.width,
                               camera.height, dilate_px=shadow_px)
        cast = vehicle_shadow(view, vehicle, pose, wlh, sun, manifest.effects.shade)
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
