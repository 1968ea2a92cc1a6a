"""A synthetic scene package with one held-out insertion whose true look is known.

The 'true' image is the background with the car relit by a fixed colour transform (dimmer,
bluer), rendered by the same renderer; the studio asset is the untransformed car.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from symdrive_core import conventions
from symdrive_core.gaussians import SH_C0, Gaussians
from symdrive_core.insertion.composite import CameraView, InsertionView
from symdrive_core.io.images import write_image, write_mask
from symdrive_core.io.ply import write_splats
from symdrive_core.splat.tensors import GaussianTensors

from ..conftest import look_at_c2w
from . import synthetic

GAIN = np.array([0.55, 0.6, 0.8], np.float32)
OFFSET = np.array([0.02, 0.03, 0.08], np.float32)
W, H, FRAMES, HELD = 96, 60, 7, 3


def relit(g: Gaussians) -> Gaussians:
    sh = g.sh.copy()
    sh[:, 0] = (g.base_colors * GAIN + OFFSET - 0.5) / SH_C0
    return Gaussians(g.means, g.quats, g.log_scales, g.opacity_logits, sh)


def relight_region(image: np.ndarray, region: np.ndarray) -> np.ndarray:
    """A stand-in harmonizer that knows the true light: the transform applied inside the region."""
    return np.where(region[..., None], image * GAIN + OFFSET, image).astype(np.float32)


def write_package(root: Path) -> tuple[Path, Gaussians]:
    """Package + background Gaussians; the car is parked 14 m down the drive."""
    root.mkdir(parents=True, exist_ok=True)
    bg, studio = synthetic.ground(), synthetic.car(1200)
    (root / "assets/box").mkdir(parents=True)
    write_splats(root / "assets/box/splats.ply", studio)
    (root / "assets/box/wlh.json").write_text(json.dumps({"wlh": list(synthetic.WLH)}))
    K = conventions.intrinsics_from_fov(W, H, np.deg2rad(60.0))
    c2ws = [look_at_c2w((0.8 * i, 0.0, 1.6), (0.8 * i + 10.0, 0.0, 0.8)) for i in range(FRAMES)]
    pose = synthetic.car_pose(x=14.0, y=-1.2, yaw=0.4)
    cf = c2ws[HELD]
    view = InsertionView(CameraView(conventions.invert_rigid(cf), K, W, H), GaussianTensors.from_gaussians(bg),
                         studio, pose)
    truth, alpha = view.render_numpy(relit(studio))
    invisible = Gaussians(studio.means, studio.quats, studio.log_scales, np.full(len(studio), -30.0, np.float32),
                          studio.sh)
    empty = view.render_numpy(invisible)[0]
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
        "effects": {"harmonize": True, "finetune": True},
        "ground_truth": {"camera": "front", "train_frames": [i for i in range(FRAMES) if i != HELD],
                         "heldout_frames": [HELD],
                         "insertion": [{"actor": "insert_0", "asset": "assets/box", "kind": "box",
                                        "wlh": list(synthetic.WLH), "pose": pose.to_json(), "camera": "front",
                                        "frame": HELD, "with": "gt/with.png", "without": "gt/without.png",
                                        "mask": "gt/mask.png", "shadow_mask": None}]},
    }
    (root / "manifest.json").write_text(json.dumps(manifest))
    write_splats(root / "background.ply", bg)
    return root / "manifest.json", bg
