"""A tiny scene whose truth is known: a two-coloured box driving over a textured floor in front
of a wall, faster than the camera that records it (the box an ``existing`` actor with its exact
poses and no assets)."""

from __future__ import annotations

import numpy as np
import torch

from symdrive_core import conventions
from symdrive_core.gaussians import Gaussians
from symdrive_core.io.images import write_image
from symdrive_core.io.points import write_points
from symdrive_core.rotations import quat_from_yaw
from symdrive_core.scene import Actor, Camera, CameraFrame, Frame, Manifest, Pose
from symdrive_core.scene.camera import CameraView
from symdrive_core.scene.manifest import DEFAULT_SHADOW_RATIO, Effects
from symdrive_core.shadows.cast import lay_shadows, vehicle_shadow_map
from symdrive_core.splat.render import render_scene
from symdrive_core.splat.tensors import GaussianTensors
from tests.conftest import look_at_c2w
from tests.optim.conftest import true_scene

W, H = 64, 40
WLH = np.array([1.6, 3.0, 1.2])
N_FRAMES = 16


def true_box(n_side: int = 15) -> Gaussians:
    """The box's surface in its own frame: red front half, blue back half, a white roof."""
    half = 0.5 * np.array([WLH[1], WLH[0], WLH[2]])
    g = np.linspace(-1, 1, n_side)
    pts = []
    for axis in range(3):
        a, b = [k for k in range(3) if k != axis]
        u, v = np.meshgrid(g, g)
        for sign in (-1, 1):
            p = np.zeros((u.size, 3))
            p[:, axis], p[:, a], p[:, b] = sign, u.ravel(), v.ravel()
            pts.append(p)
    pts = np.unique(np.concatenate(pts), axis=0) * half
    colours = np.where(pts[:, :1] > 0, [0.85, 0.1, 0.1], [0.1, 0.2, 0.85])
    colours[pts[:, 2] > 0.99 * half[2]] = 0.95
    n = len(pts)
    return Gaussians.from_activated(pts, np.tile([1.0, 0, 0, 0], (n, 1)), np.full((n, 3), 0.1), np.full(n, 0.98),
                                    colours)


def street() -> Gaussians:
    """The shared wall-and-floor scene with a flat floor (a thick one would hide the box's lower half
    from every camera)."""
    g = true_scene()
    floor = g.means[:, 2] == 0.0
    g.log_scales[floor, 2] = np.log(0.02)
    return g


def box_pose(i: int) -> Pose:
    """Along +X at 0.9 m per frame (the camera makes 0.4), turning slightly, on the floor."""
    return Pose(np.array([-3.0 + 0.9 * i, 2.8, 0.5 * WLH[2]]), quat_from_yaw(0.02 * i))


def camera_c2w(i: int) -> np.ndarray:
    return look_at_c2w((0.4 * i, -2.0, 1.6), (0.4 * i + 1.0, 6.0, 0.8))


def write_moving_box(root, sun=None):
    """Write the package under ``root``; (root, the box's true Gaussians, per frame the truth
    {rgb, mask, background}, held-out frames). With ``sun`` (the direction light travels) the box
    casts its shadow on the recorded images and the scene's effects say so; ``background`` is the
    street without the box and without its shadow."""
    root.mkdir(parents=True, exist_ok=True)
    scene, box = street(), true_box()
    bg, car = GaussianTensors.from_gaussians(scene), GaussianTensors.from_gaussians(box)
    K = conventions.intrinsics_from_fov(W, H, np.deg2rad(75))
    frames, cam_frames, truth = [], [], {}
    for i in range(N_FRAMES):
        c2w = camera_c2w(i)
        view = CameraView(conventions.invert_rigid(c2w), K, W, H)
        with torch.no_grad():
            out = render_scene(bg, [(car, box_pose(i), 1)], view)
            empty = render_scene(bg, [], view)
        truth[i] = {"rgb": out["rgb"].clamp(0, 1).numpy(), "mask": out["instance"][..., 0].numpy() > 0.5,
                    "background": empty["rgb"].clamp(0, 1).numpy()}
        if sun is not None:
            smap = vehicle_shadow_map(box, box_pose(i), WLH, sun)
            truth[i]["rgb"], truth[i]["shadow"] = lay_shadows(
                truth[i]["rgb"], [out["instance"][..., 0].numpy()], truth[i]["background"],
                empty["depth"][..., 0].numpy(), [smap], c2w, K, DEFAULT_SHADOW_RATIO)
        write_image(root / f"img/{i:03d}.png", truth[i]["rgb"])
        frames.append(Frame(i, 0.1 * i))
        cam_frames.append(CameraFrame(K, c2w, conventions.invert_rigid(c2w), f"img/{i:03d}.png"))
    rng = np.random.default_rng(1)
    write_points(root / "points.ply", scene.means + rng.normal(scale=0.05, size=scene.means.shape),
                 np.clip(scene.base_colors, 0, 1))
    heldout = list(range(2, N_FRAMES, 4))
    actor = Actor("car_1", "existing", None, None, [box_pose(i) for i in range(N_FRAMES)], WLH, 1)
    m = Manifest(name="moving-box", frames=frames, cameras=[Camera("front", W, H, cam_frames)], actors=[actor],
                 background_points="points.ply",
                 ground_truth={"train_frames": [i for i in range(N_FRAMES) if i not in heldout],
                               "heldout_frames": heldout}, root=root,
                 effects=Effects(shadows=sun is not None, sun_direction=sun))
    m.save(root / "manifest.json")
    return root, box, truth, heldout


def traffic_truth_entries(root, truth, removed=(2, 6)) -> tuple[dict, list[dict]]:
    """Write the box's mask of every frame and removals of the box at the ``removed`` frames (the
    truth's street without it) under ``root``: (``ground_truth.vehicles``, the removals'
    ``ground_truth.edits`` entries)."""
    from symdrive_core.io.images import write_mask

    frames = {}
    for f, t in truth.items():
        write_mask(root / f"gt/vehicles/{f:06d}.png", t["mask"])
        frames[str(f)] = f"gt/vehicles/{f:06d}.png"
    edits = []
    for j, f in enumerate(removed):
        write_image(root / f"gt/edits/{j}/image.png", truth[f]["background"])
        write_mask(root / f"gt/edits/{j}/mask.png", truth[f]["mask"])
        edits.append({"kind": "remove", "actor": "car_1", "camera": "front", "frame": f, "pose": None,
                      "image": f"gt/edits/{j}/image.png", "mask": f"gt/edits/{j}/mask.png"})
    return {"camera": "front", "frames": frames}, edits
