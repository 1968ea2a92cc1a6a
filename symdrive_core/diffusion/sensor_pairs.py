"""Training pairs whose target a second camera of the rig recorded.

A rectified rig's second camera, imported as lateral ground truth with its ``sensor`` named
(:mod:`symdrive_core.importers.stereo`), sees every frame from the trained camera's +x at the
baseline: real pixels of the lateral view the restorer must produce there, beside a render that
carries the reconstruction's real degradation at that camera (it never trained on it). The
synthetic pairs of :func:`.data.make_pairs` only imitate that degradation. So at the pair frames
(the training frames) each such view becomes pairs of its own: the conditions made as a
synthetic pair's around that camera (renders ``d`` to either side), the render at it as the
degraded start, the pair frames warped into it as the guide, the recorded image the target.
Held-out frames are never pair frames, so their second-camera images stay for scoring alone.

Stored beside the synthetic pairs in one file as ``sensor_left``, ``sensor_target``,
``sensor_right`` [P, H, W, 3] with ``sensor_frame`` and ``sensor_offset`` (d) per pair, and per
view ``sensor_start`` [V, H, W, 3] (and with warps ``sensor_warp``, ``sensor_warp_mask``), with
``sensor_view`` [P] indexing them; :class:`.data.PairSet` reads them as more pairs.
"""

from __future__ import annotations

import numpy as np

from .. import conventions
from ..errors import InputError
from ..io.images import read_image
from ..scene.ground_truth import LateralView, lateral_views


def sensor_views(manifest, camera: str, frames) -> list[LateralView]:
    """The lateral truth of package camera ``camera`` that a recorded camera gave at ``frames``
    (rendered truth is no sensor's)."""
    keep = set(frames)
    return [v for v in lateral_views(manifest, camera) if v.sensor is not None and v.frame in keep]


def sensor_pairs(manifest, views: list[LateralView], offsets, render, warper=None, *,
                 progress: bool = True) -> dict[str, np.ndarray]:
    """The ``sensor_*`` tensors of ``views`` (see the module); ``warper`` (its sources the pair
    frames) adds each view's warp and mask, computed as sampling computes them there."""
    from tqdm import tqdm

    left, target, right, offs, frames, view_of, starts, warps, masks = ([] for _ in range(9))
    for k, v in enumerate(tqdm(views, desc="sensor pairs", unit="view", disable=not progress)):
        path = manifest.resolve(v.image)
        truth = read_image(path, channels=3)
        if truth.shape[:2] != (v.camera.height, v.camera.width):
            raise InputError(path, f"image is {truth.shape[1]}x{truth.shape[0]}; the camera it is lateral "
                             f"truth of is {v.camera.width}x{v.camera.height}", f"ground_truth.lateral (frame {v.frame})")
        raw = render(v.camera)
        for d in offsets:
            left.append(conventions.to_uint8(render(v.camera.shifted(-d))))
            right.append(conventions.to_uint8(render(v.camera.shifted(d))))
            target.append(conventions.to_uint8(truth))
            offs.append(d)
            frames.append(v.frame)
            view_of.append(k)
        starts.append(conventions.to_uint8(raw))
        if warper is not None:
            depth = render.depth(v.camera, warper.config.min_alpha)
            w = warper.warp(v.frame, v.camera.K, v.camera.camera_to_world, v.camera.width, v.camera.height,
                            raw, depth)
            warps.append(conventions.to_uint8(w.image))
            masks.append(w.mask.astype(np.uint8))
    out = {
        "sensor_left": np.stack(left), "sensor_target": np.stack(target), "sensor_right": np.stack(right),
        "sensor_offset": np.asarray(offs, np.float32), "sensor_frame": np.asarray(frames, np.int32),
        "sensor_view": np.asarray(view_of, np.int32), "sensor_start": np.stack(starts),
    }
    if warper is not None:
        out |= {"sensor_warp": np.stack(warps), "sensor_warp_mask": np.stack(masks)}
    return out
