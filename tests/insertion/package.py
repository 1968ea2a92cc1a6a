"""A synthetic scene package with one held-out insertion whose true look is known.

The 'true' image is the background with the car relit by a fixed colour transform (dimmer,
bluer), rendered by the same renderer; the studio asset is the untransformed car. With a sun,
the truth also has the car's hard shadow: ground pixels whose ray to the sun hits the exact box
(a slab test, independent of any splat code) keep ``SHADOW_RATIO`` of their linear light.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from symdrive_core import conventions
from symdrive_core.gaussians import SH_C0, Gaussians
from symdrive_core.insertion.insert import insertion_view
from symdrive_core.io.images import write_image, write_mask
from symdrive_core.io.ply import write_splats
from symdrive_core.scene.camera import CameraView
from symdrive_core.splat.tensors import GaussianTensors

from ..conftest import look_at_c2w
from . import synthetic

GAIN = np.array([0.55, 0.6, 0.8], np.float32)
OFFSET = np.array([0.02, 0.03, 0.08], np.float32)
W, H, FRAMES, HELD = 96, 60, 7, 3
SHADOW_RATIO = 0.35
SUN = (-0.45, 0.55, -0.7)  # light travels away from the camera's left: the shadow falls beside the car


def relit(g: Gaussians) -> Gaussians:
    sh = g.sh.copy()
    sh[:, 0] = (g.base_colors * GAIN + OFFSET - 0.5) / SH_C0
    return Gaussians(g.means, g.quats, g.log_scales, g.opacity_logits, sh)


def relight_region(image: np.ndarray, region: np.ndarray) -> np.ndarray:
    """A stand-in harmonizer that knows the true light: the transform applied inside the region."""
    return np.where(region[..., None], image * GAIN + OFFSET, image).astype(np.float32)


def box_shadow(view, pose, wlh, sun) -> np.ndarray:
    """Bool [H, W]: the pixel's ground point (z = 0) cannot see the sun past the box."""
    from symdrive_core.shadows.region import ground_hits

    cam = view.camera
    xy, hit = ground_hits(cam.camera_to_world, cam.K, cam.width, cam.height, 0.0)
    p = np.concatenate([xy, np.zeros(xy.shape[:-1] + (1,))], -1)
    o = (p - pose.translation) @ pose.R  # box frame
    d = -np.asarray(sun, np.float64) / np.linalg.norm(sun) @ pose.R  # towards the sun
    half = np.array([wlh[1], wlh[0], wlh[2]]) / 2
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (-half - o) / d, (half - o) / d
    near = np.nanmax(np.minimum(t1, t2), -1)
    far = np.nanmin(np.maximum(t1, t2), -1)
    return hit & (far >= np.maximum(near, 0.0))


def write_package(root: Path, sun=None) -> tuple[Path, Gaussians]:
    """Package + background Gaussians; the car is parked 14 m down the drive (``sun``: the truth
    has its shadow, and the manifest says where the sun is and how dark shade is)."""
    root.mkdir(parents=True, exist_ok=True)
    bg, studio = synthetic.ground(), synthetic.car(1200)
    (root / "assets/box").mkdir(parents=True)
    write_splats(root / "assets/box/splats.ply", studio)
    (root / "assets/box/wlh.json").write_text(json.dumps({"wlh": list(synthetic.WLH)}))
    K = conventions.intrinsics_from_fov(W, H, np.deg2rad(60.0))
    c2ws = [look_at_c2w((0.8 * i, 0.0, 1.6), (0.8 * i + 10.0, 0.0, 0.8)) for i in range(FRAMES)]
    pose = synthetic.car_pose(x=14.0, y=-1.2, yaw=0.4)
    cf = c2ws[HELD]
    view = insertion_view(CameraView(conventions.invert_rigid(cf), K, W, H), GaussianTensors.from_gaussians(bg),
                         studio, pose)
    truth, alpha = view.render_numpy(relit(studio))
    invisible = Gaussians(studio.means, studio.quats, studio.log_scales, np.full(len(studio), -30.0, np.float32),
                          studio.sh)
    empty = view.render_numpy(invisible)[0]
    shadow = None
    if sun is not None:
        from symdrive_core.conventions import linear_to_srgb, srgb_to_linear

        shadow = box_shadow(view, pose, synthetic.WLH, sun) & (alpha < 0.5)
        truth = np.where(shadow[..., None], linear_to_srgb(SHADOW_RATIO * srgb_to_linear(truth)), truth)
        write_mask(root / "gt/shadow.png", shadow.astype(np.float32))
    write_image(root / "gt/with.png", truth)
    write_image(root / "gt/without.png", empty)
    write_mask(root / "gt/mask.png", (alpha > 0.5).astype(np.float32))
    manifest = {
        "format": "symdrive-scene", "version": 1, "name": "synthetic-insertion",
        "frames": [{"index": i, "timestamp": 0.1 * i} for i in range(FRAMES)],
        "cameras": [{"name": "front", "width": W, "height": H, "frames": [
            {"K": K.tolist(), "camera_to_world": c.tolist(), "world_to_camera": conventions.invert_rigid(c).tolist()}
            for c in c2ws]}],
        "background": {"splats": None},
        "actors": [{"id": "insert_0", "kind": "inserted", "assets": {"splats": "assets/box/splats.ply"},
                    "wlh": list(synthetic.WLH),
                    "poses": [pose.to_json() if i == HELD else None for i in range(FRAMES)]}],
        "effects": {"harmonize": True, "finetune": True, "shadows": sun is not None,
                    "sun_direction": None if sun is None else list(sun),
                    "shadow_ratio": SHADOW_RATIO if sun is not None else None},
        "ground_truth": {"camera": "front", "train_frames": [i for i in range(FRAMES) if i != HELD],
                         "heldout_frames": [HELD],
                         "insertion": [{"actor": "insert_0", "asset": "assets/box", "kind": "box",
                                        "wlh": list(synthetic.WLH), "pose": pose.to_json(), "camera": "front",
                                        "frame": HELD, "with": "gt/with.png", "without": "gt/without.png",
                                        "mask": "gt/mask.png",
                                        "shadow_mask": None if shadow is None else "gt/shadow.png"}]},
    }
    (root / "manifest.json").write_text(json.dumps(manifest))
    write_splats(root / "background.ply", bg)
    return root / "manifest.json", bg
