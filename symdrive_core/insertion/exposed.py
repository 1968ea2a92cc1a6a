"""What an edit of a recorded vehicle exposes, filled by the restorer as inpainting.

Removing, moving or retiming a recorded car uncovers pixels where it was: the road under it, what
stood behind it. Where other frames saw them the background has them; where no frame did (a car
that drove ahead of the ego all along) it has a hole or a smear. The exposed region of a frame is
the edited vehicles' pixels where the drive saw them (their recorded poses) that no vehicle covers
after the edit; of it, the pixels whose surface (the background's depth) no training frame saw
past the recorded vehicles are what the same RePaint sampler that harmonizes inserted vehicles
re-draws, everything else kept bit for bit. Occlusion by the static scene is not tested: a surface
counts as seen by a frame that has it in view with no recorded vehicle's box in between.
"""

from __future__ import annotations

import numpy as np

from ..conventions import pixel_rays_camera
from ..optim.decompose import Track, tracks
from ..scene import Manifest
from ..scene.camera import CameraView
from ..shadows.region import dilate

VEHICLE_ALPHA = 0.5  # a pixel belongs to a vehicle where its accumulated alpha is at least this


def edited_here(manifest: Manifest, frame: int) -> list[str]:
    """Ids of the recorded vehicles an edit removed, moved or retimed at ``frame``."""
    return [a.id for a in manifest.actors if frame in a.edited_frames()]


def exposed_region(recorded: dict[str, np.ndarray], edited: dict[str, np.ndarray], actor_ids: list[str],
                   dilate_px: int = 2) -> np.ndarray | None:
    """[H, W] bool: ``actor_ids``' pixels in the recorded frame (``recorded``: actor id -> alpha,
    rendered at recorded poses), grown by ``dilate_px`` for their soft rims, that no vehicle of the
    edited frame (``edited``: actor id -> alpha) covers; None when there is nothing to expose."""
    was = [recorded[a] >= VEHICLE_ALPHA for a in actor_ids if a in recorded]
    if not was:
        return None
    region = dilate(np.logical_or.reduce(was), dilate_px)
    for alpha in edited.values():
        region &= alpha < VEHICLE_ALPHA
    return region if region.any() else None


def unseen(manifest: Manifest, view: CameraView, depth: np.ndarray, region: np.ndarray,
           frames: list[int]) -> np.ndarray:
    """[H, W] bool: the pixels of ``region`` whose surface, at ``depth`` (camera z; 0: nothing
    rendered), no camera of ``frames`` has in view without a recorded vehicle's box in front of it."""
    ys, xs = np.nonzero(region & (depth > 0))
    out = region & (depth <= 0)
    if len(ys) == 0:
        return out
    K, c2w = view.K, np.linalg.inv(view.world_to_camera)
    rays = pixel_rays_camera(K, xs, ys)
    points = (rays * depth[ys, xs][:, None]) @ c2w[:3, :3].T + c2w[:3, 3]
    seen = np.zeros(len(points), bool)
    recorded = tracks(manifest)
    for cam in manifest.cameras:
        for f in frames:
            seen |= _seen_from(CameraView.of_frame(cam, f), points, recorded, f)
    out[ys[~seen], xs[~seen]] = True
    return out


def _seen_from(view: CameraView, points: np.ndarray, recorded: list[Track], frame: int) -> np.ndarray:
    cam = points @ view.world_to_camera[:3, :3].T + view.world_to_camera[:3, 3]
    z = np.maximum(cam[:, 2], 1e-9)
    u = cam[:, 0] / z * view.K[0, 0] + view.K[0, 2]
    v = cam[:, 1] / z * view.K[1, 1] + view.K[1, 2]
    ok = (cam[:, 2] > 0.1) & (u >= 0) & (u < view.width) & (v >= 0) & (v < view.height)
    centre = np.linalg.inv(view.world_to_camera)[:3, 3]
    for t in recorded:
        pose = t.poses[frame]
        if pose is not None and ok.any():
            ok &= ~_segment_hits_box(centre, points, pose, t.half)
    return ok


def _segment_hits_box(start: np.ndarray, ends: np.ndarray, pose, half: np.ndarray) -> np.ndarray:
    """[N] whether the segments start -> ends[i] cross the box (slab test in its local frame)."""
    a = (start - pose.translation) @ pose.R
    b = (ends - pose.translation) @ pose.R
    d = b - a
    with np.errstate(divide="ignore", invalid="ignore"):
        t0, t1 = (-half - a) / d, (half - a) / d
    lo = np.nanmax(np.where(np.isfinite(t0), np.minimum(t0, t1), np.where(np.abs(a) <= half, -np.inf, np.inf)), 1)
    hi = np.nanmin(np.where(np.isfinite(t0), np.maximum(t0, t1), np.where(np.abs(a) <= half, np.inf, -np.inf)), 1)
    return (lo <= hi) & (hi >= 0.0) & (lo <= 0.999)


def inpaint_region(manifest: Manifest, view: CameraView, recorded: dict[str, np.ndarray],
                   edited: dict[str, np.ndarray], actor_ids: list[str], background_depth: np.ndarray,
                   dilate_px: int = 2) -> np.ndarray | None:
    """What to inpaint in an edited frame: the exposed region (:func:`exposed_region`) where no
    training frame saw the surface behind (:func:`unseen`); None when that is nothing."""
    from ..scene.ground_truth import split_frames

    region = exposed_region(recorded, edited, actor_ids, dilate_px)
    if region is None:
        return None
    region = unseen(manifest, view, background_depth, region, split_frames(manifest)[0])
    return region if region.any() else None
