"""A synthetic scene package whose truth is a known set of Gaussians (rendered by our rasterizer)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from symdrive_core import conventions
from symdrive_core.gaussians import Gaussians
from symdrive_core.io.images import write_image
from symdrive_core.io.points import write_points
from symdrive_core.scene import Camera, CameraFrame, Frame, Manifest
from symdrive_core.splat.tensors import GaussianTensors
from tests.conftest import look_at_c2w

W, H = 48, 32


def true_scene(seed=0) -> Gaussians:
    """A textured wall (y = 6) and floor (z = 0) of opaque, overlapping Gaussians."""
    rng = np.random.default_rng(seed)
    xs, zs = np.meshgrid(np.linspace(-8, 12, 44), np.linspace(-0.5, 6, 16))
    wall = np.stack([xs.ravel(), np.full(xs.size, 6.0), zs.ravel()], 1)
    xf, yf = np.meshgrid(np.linspace(-8, 12, 44), np.linspace(-1, 6, 14))
    floor = np.stack([xf.ravel(), yf.ravel(), np.zeros(xf.size)], 1)
    means = np.concatenate([wall, floor])
    n = len(means)
    colors = np.clip(0.5 + 0.35 * np.sin(means[:, :1] * [1.3, 0.7, 2.1] + means[:, 2:] * 1.7)
                     + 0.1 * rng.normal(size=(n, 3)), 0.05, 0.95)
    return Gaussians.from_activated(means, np.tile([1.0, 0, 0, 0], (n, 1)), np.full((n, 3), 0.3),
                                    np.full(n, 0.95), colors)


def render_truth(g: Gaussians, c2w, K, depth=False):
    from symdrive_core.splat import rasterize

    t = GaussianTensors.from_gaussians(g)
    w2c = torch.tensor(conventions.invert_rigid(c2w), dtype=torch.float32)
    with torch.no_grad():
        rgb, alpha, info = rasterize(t.means, t.quats, t.scales, t.opacities, t.sh, w2c,
                                     torch.tensor(K, dtype=torch.float32), W, H, render_depth=depth)
    d = None
    if depth:
        d = torch.where(alpha[..., 0] > 0.5, info["depth"][..., 0], torch.zeros(())).numpy()
    return rgb.clamp(0, 1).numpy(), d


def write_package(root, n_frames=6, offsets=(-0.5, 0.5)):
    """Camera sliding along +X, looking at the wall; every 3rd frame held out."""
    root.mkdir(parents=True, exist_ok=True)
    g = true_scene()
    K = conventions.intrinsics_from_fov(W, H, np.deg2rad(70))
    frames, cam_frames = [], []
    for i in range(n_frames):
        c2w = look_at_c2w((0.4 * i, 0.0, 1.5), (0.4 * i, 6.0, 1.2))
        rgb, depth = render_truth(g, c2w, K, depth=True)
        write_image(root / f"img/{i:03d}.png", rgb)
        write_image(root / f"depth/{i:03d}.exr", depth, dtype="float")
        frames.append(Frame(i, 0.1 * i))
        cam_frames.append(CameraFrame(K, c2w, conventions.invert_rigid(c2w), f"img/{i:03d}.png", f"depth/{i:03d}.exr"))
    lateral = []
    for off in offsets:
        entry = {}
        for i in range(0, n_frames, 2):
            rgb, _ = render_truth(g, conventions.lateral_shift(cam_frames[i].camera_to_world, off), K)
            write_image(root / f"lat/{off:+.1f}/{i:03d}.png", rgb)
            entry[str(i)] = f"lat/{off:+.1f}/{i:03d}.png"
        lateral.append({"offset_m": off, "camera": "front", "frames": entry})
    rng = np.random.default_rng(1)
    pts = g.means + rng.normal(scale=0.1, size=g.means.shape)
    write_points(root / "points.ply", pts, np.clip(g.base_colors + rng.normal(scale=0.15, size=pts.shape), 0, 1))
    heldout = list(range(1, n_frames, 3))
    m = Manifest(name="synthetic", frames=frames, cameras=[Camera("front", W, H, cam_frames)], actors=[],
                 background_points="points.ply",
                 ground_truth={"train_frames": [i for i in range(n_frames) if i not in heldout],
                               "heldout_frames": heldout, "lateral": lateral}, root=root)
    m.save(root / "manifest.json")
    return root, g


@pytest.fixture(scope="module")
def synthetic_package(tmp_path_factory):
    return write_package(tmp_path_factory.mktemp("synthetic") / "pkg")


@pytest.fixture
def command_config(monkeypatch):
    """``command_config(ARGS)``: the :class:`ReconstructConfig` that ``symdrive reconstruct ARGS``
    composes, caught where it would start fitting (how each option reaches the fit, without one)."""
    from symdrive_core.cli import main
    from symdrive_core.optim import reconstruct

    class Stop(Exception):
        pass

    seen = []

    def stop(manifest, out, cfg, **kwargs):
        seen.append(cfg)
        raise Stop

    monkeypatch.setattr(reconstruct, "reconstruct", stop)

    def config(args: list[str]):
        with pytest.raises(Stop):
            main(["reconstruct", *args])
        return seen[-1]

    return config
