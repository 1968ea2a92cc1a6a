"""Quality of a reconstruction against the package's Cycles ground truth.

``evaluate_heldout``: the training drive's held-out frames. ``evaluate_lateral``: the same
drive seen from cameras moved sideways (the degradation the restoration stage must fix),
one row per offset as ``report.json``'s ``metrics.lateral`` expects, method ``raw_3dgs``.
PSNR in dB and SSIM (3DGS flavour, ``symdrive_core.metrics``) on [0, 1] images, averaged
over frames.
"""

from __future__ import annotations

import numpy as np

from ..gaussians import Gaussians
from ..io.images import read_image
from ..metrics import psnr, ssim
from ..scene import Manifest
from ..splat.render import render_gaussians
from ..world.package import lateral_views, split_frames


def _score(pred: np.ndarray, target: np.ndarray) -> tuple[float, float]:
    return psnr(pred, target), ssim(pred, target)


def evaluate_heldout(manifest: Manifest, gaussians: Gaussians, frames: list[int] | None = None,
                     camera: str | None = None) -> dict:
    """{"psnr_heldout", "ssim_heldout", "frames"} over the held-out training-drive frames."""
    frames = split_frames(manifest)[1] if frames is None else list(frames)
    if not frames:
        raise ValueError("evaluate_heldout: the package holds out no frames")
    cam = manifest.camera(camera) if camera else manifest.cameras[0]
    scores = []
    for i in frames:
        cf = cam.frames[i]
        pred = render_gaussians(gaussians, cf.K, cf.world_to_camera, cam.width, cam.height)
        scores.append(_score(pred, read_image(manifest.resolve(cf.image), channels=3)))
    p, s = np.mean(scores, axis=0)
    return {"psnr_heldout": round(float(p), 3), "ssim_heldout": round(float(s), 4), "frames": len(frames)}


def evaluate_lateral(manifest: Manifest, gaussians: Gaussians, method: str = "raw_3dgs") -> list[dict]:
    """One row per lateral offset: {"offset_m", "method", "psnr", "ssim", "frames"}."""
    by_offset: dict[float, list[tuple[float, float]]] = {}
    for v in lateral_views(manifest):
        pred = render_gaussians(gaussians, v.K, v.world_to_camera, v.width, v.height)
        by_offset.setdefault(v.offset_m, []).append(_score(pred, read_image(manifest.resolve(v.image), channels=3)))
    rows = []
    for off in sorted(by_offset, key=lambda o: (abs(o), o)):
        p, s = np.mean(by_offset[off], axis=0)
        rows.append({"offset_m": off, "method": method, "psnr": round(float(p), 3), "ssim": round(float(s), 4),
                     "frames": len(by_offset[off])})
    return rows
