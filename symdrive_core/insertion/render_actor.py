"""Render one inserted actor along its trajectory: image, vehicle mask and harmonization region.

Outputs under ``out``: ``<camera>/<frame>.png`` (the insertion, with its cast shadow where the
scene has a sun), ``<camera>/<frame>.mask.png`` (the vehicle's accumulated alpha),
``<camera>/<frame>.shadow.png`` (how much sun it blocks, sunny scenes only) and
``<camera>/<frame>.region.png`` (vehicle ∪ shadow region, what harmonization may change).
Frames where the actor is absent or outside the frustum are skipped; every file is written
atomically.
"""

from __future__ import annotations

from pathlib import Path

from tqdm import tqdm

from ..errors import InputError
from ..io.images import write_image, write_mask
from ..io.ply import read_splats
from ..scene import Manifest, box_corners_world, box_in_frustum, vehicle_local_box
from ..scene.camera import CameraView
from .assets import actor_gaussians
from .config import MESH_SAMPLES
from .insert import insert_frame


def insert_actor(manifest: Manifest, actor_id: str, out, *, background=None, flip: bool = False,
                 from_mesh: bool = False, n_samples: int = MESH_SAMPLES, progress: bool = True) -> int:
    """Write every visible frame of ``actor_id`` inserted into the background; returns the count."""
    from ..splat.tensors import GaussianTensors

    try:
        actor = manifest.actor(actor_id)
    except KeyError:
        raise InputError(manifest.path or manifest.root, f"no actor with id {actor_id!r}", "actors") from None
    if actor.wlh is None:
        raise InputError(manifest.path or manifest.root, f"actor {actor_id!r} needs a wlh size", "actors.wlh")
    bg_path = background or (manifest.resolve(manifest.background_splats) if manifest.background_splats else None)
    if bg_path is None:
        raise InputError(manifest.path or manifest.root, "no background splats: pass --gaussians or reconstruct "
                         "the package first", "background.splats")
    bg = GaussianTensors.from_gaussians(read_splats(bg_path, drop_invalid=True))
    vehicle = actor_gaussians(manifest, actor, flip=flip, from_mesh=from_mesh, n_samples=n_samples)
    lo, hi = vehicle_local_box(actor.wlh)
    jobs = []
    for cam in manifest.cameras:
        for fi, cf in enumerate(cam.frames):
            pose = actor.pose(fi)
            if pose is not None and box_in_frustum(box_corners_world(lo, hi, pose.R, pose.translation),
                                                   cf.world_to_camera, cf.K, cam.width, cam.height):
                jobs.append((cam, fi, CameraView.of_frame(cam, fi), pose))
    out = Path(out)
    for cam, fi, view, pose in tqdm(jobs, desc=f"insert {actor_id}", unit="frame", disable=not progress):
        frame = insert_frame(manifest, bg, vehicle, pose, actor.wlh, view)
        base = out / cam.name / f"{fi:06d}"
        write_mask(base.with_suffix(".mask.png"), frame.vehicle_alpha)
        write_mask(base.with_suffix(".region.png"), frame.region.astype("float32"))
        if frame.shadow is not None:
            write_mask(base.with_suffix(".shadow.png"), frame.shadow.occlusion)
        write_image(base.with_suffix(".png"), frame.image)
    return len(jobs)
