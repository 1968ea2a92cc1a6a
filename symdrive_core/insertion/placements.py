"""Placements of an inserted vehicle: the held-out ground-truth ones and the training views.

The world's ``ground_truth["insertion"]`` entries put a vehicle at a fixed world pose and give
the Cycles render of it truly in the scene at one held-out frame. The same parked vehicle seen
from the drive's *training* frames gives the views to harmonize and fine-tune on, so the
held-out view never enters the fine-tune.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import conventions
from ..scene import Manifest, Pose
from ..scene.camera import CameraView
from ..scene.ground_truth import truth_camera


@dataclass
class HeldOut:
    index: int
    asset: str  # asset folder, relative to the package
    pose: Pose
    wlh: np.ndarray
    frame: int
    camera_name: str
    camera: CameraView
    with_image: str
    mask: str
    shadow_mask: str | None


def held_out_placements(manifest: Manifest) -> list[HeldOut]:
    out = []
    for k, e in enumerate((manifest.ground_truth or {}).get("insertion", [])):
        cam = manifest.camera(e["camera"]) if "camera" in e else truth_camera(manifest)
        pose = Pose(np.asarray(e["pose"]["translation"], dtype=np.float64),
                    np.asarray(e["pose"]["rotation"], dtype=np.float64))
        out.append(HeldOut(k, e["asset"], pose, np.asarray(e["wlh"], dtype=np.float64), int(e["frame"]), cam.name,
                           CameraView.of_frame(cam, int(e["frame"])), e["with"], e["mask"],
                           e.get("shadow_mask")))
    return out


def sees_whole_box(camera: CameraView, pose: Pose, wlh, *, min_depth: float = 3.0, min_pixels: float = 150.0) -> bool:
    """True when every box corner is in front of the camera, inside the image, and the box is
    big enough on screen to learn from."""
    uv, z = conventions.project_points(pose.apply(conventions.vehicle_box_corners(wlh)), camera.world_to_camera,
                                       camera.K)
    if np.any(z < min_depth):
        return False
    inside = (uv[:, 0] >= 0) & (uv[:, 0] <= camera.width) & (uv[:, 1] >= 0) & (uv[:, 1] <= camera.height)
    area = np.ptp(uv[:, 0]) * np.ptp(uv[:, 1])
    return bool(inside.all() and area >= min_pixels)


def training_views(manifest: Manifest, placement: HeldOut, frames: list[int], n_views: int = 6) -> list[int]:
    """Up to ``n_views`` of ``frames`` (not the held-out one) that see the whole vehicle, nearest
    in time to the held-out frame first."""
    ok = [fi for fi in frames if fi != placement.frame
          and sees_whole_box(camera_view(manifest, fi, placement.camera_name), placement.pose, placement.wlh)]
    return sorted(ok, key=lambda f: (abs(f - placement.frame), f))[:n_views]


def camera_view(manifest: Manifest, frame: int, camera: str | None = None) -> CameraView:
    return CameraView.of_frame(manifest.camera(camera) if camera else manifest.cameras[0], frame)
