"""Shared fixtures: tiny scene packages and splat clouds made in the test, never downloaded."""

from __future__ import annotations

import atexit
import json
import os
import sys
from pathlib import Path

import numpy as np
import pytest

from symdrive_core import conventions
from symdrive_core.gaussians import Gaussians
from symdrive_core.io.ply import write_splats


def random_gaussians(n: int, degree: int = 0, seed: int = 0, center=(0.0, 0.0, 0.0), spread=1.0) -> Gaussians:
    rng = np.random.default_rng(seed)
    k = (degree + 1) ** 2
    return Gaussians(
        means=(np.asarray(center) + spread * rng.normal(size=(n, 3))).astype(np.float32),
        quats=rng.normal(size=(n, 4)).astype(np.float32),
        log_scales=(rng.normal(size=(n, 3)) - 3.0).astype(np.float32),
        opacity_logits=rng.normal(size=n).astype(np.float32),
        sh=(0.3 * rng.normal(size=(n, k, 3))).astype(np.float32),
    )


def look_at_c2w(eye, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """OpenCV camera-to-world looking from ``eye`` at ``target`` (y down, z forward)."""
    eye, target, up = (np.asarray(v, dtype=np.float64) for v in (eye, target, up))
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    c2w = np.eye(4)
    c2w[:3, 0], c2w[:3, 1], c2w[:3, 2], c2w[:3, 3] = x, y, z, eye
    return c2w


def manifest_dict(n_frames=3, width=32, height=24, actors=("car_0",), lateral=(), sun=None,
                  harmonize=False, background="background.ply") -> dict:
    """A small valid manifest: a camera driving along +X, actors ahead of it."""
    K = conventions.intrinsics_from_fov(width, height, np.deg2rad(60.0))
    frames, cam_frames = [], []
    for i in range(n_frames):
        c2w = look_at_c2w((i * 1.0, 0.0, 1.5), (i * 1.0 + 10.0, 0.0, 1.0))
        frames.append({"index": i, "timestamp": i * 0.1})
        cam_frames.append({"K": K.tolist(), "camera_to_world": c2w.tolist(),
                           "world_to_camera": conventions.invert_rigid(c2w).tolist()})
    return {
        "format": "symdrive-scene", "version": 1, "name": "tiny",
        "frames": frames,
        "cameras": [{"name": "front", "width": width, "height": height, "frames": cam_frames}],
        "background": {"splats": background},
        "actors": [{"id": a, "kind": "inserted", "assets": {"splats": f"{a}.ply"}, "wlh": [1.8, 4.5, 1.5],
                    "poses": [{"translation": [8.0 + i, 2.0 * j - 1.0, 0.75], "rotation": [1, 0, 0, 0]}
                              for i in range(n_frames)]} for j, a in enumerate(actors)],
        "effects": {"lateral_offsets": list(lateral), "harmonize": harmonize, "shadows": sun is not None,
                    "sun_direction": sun},
    }


def write_recorded_images(root: Path, manifest: dict, background: Gaussians) -> None:
    """Give every frame of ``manifest`` (a :func:`manifest_dict`) a recorded image under
    ``root/images``: the background's own render, so reconstruction and scoring have a drive."""
    from symdrive_core.io.images import write_image
    from symdrive_core.scene.camera import CameraView
    from symdrive_core.splat.render import SplatRenderer

    render = SplatRenderer(background)
    for cam in manifest["cameras"]:
        for i, f in enumerate(cam["frames"]):
            rel = f"images/{cam['name']}/{i:06d}.png"
            write_image(root / rel, render(CameraView(f["world_to_camera"], f["K"], cam["width"], cam["height"])))
            f["image"] = rel


@pytest.fixture
def make_package(tmp_path):
    """Write a tiny scene package (manifest + splat files) and return the manifest path."""

    def _make(name="pkg", **kwargs) -> Path:
        root = tmp_path / name
        root.mkdir()
        d = manifest_dict(**kwargs)
        if d["background"]["splats"]:
            write_splats(root / d["background"]["splats"], random_gaussians(200, 0, 1, (10, 0, 1), 3.0))
        for j, a in enumerate(d["actors"]):
            write_splats(root / a["assets"]["splats"], random_gaussians(50, 1, 10 + j, spread=0.8))
        (root / "manifest.json").write_text(json.dumps(d))
        return root / "manifest.json"

    return _make


@pytest.fixture(scope="session")
def moving_box(tmp_path_factory):
    """The moving-box drive (:mod:`tests.optim.moving_box`) reconstructed once with a small budget:
    (package root, ReconstructResult, per-frame truth, the box's true Gaussians, held-out frames).
    Tests that edit the package copy it."""
    from symdrive_core.optim.reconstruct import ReconstructConfig, reconstruct
    from symdrive_core.scene import load_manifest
    from tests.optim.moving_box import write_moving_box

    root, box, truth, heldout = write_moving_box(tmp_path_factory.mktemp("moving_box") / "pkg")
    cfg = ReconstructConfig(iters=600, densify_from=100, densify_every=100, sky_points=0, actor_points=600,
                            checkpoint_every=10_000, sh_degree=0)
    return root, reconstruct(load_manifest(root), root / "reconstruction", cfg, progress=False), truth, box, heldout


def _end_now(status: int) -> None:
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except Exception:
            pass
    os._exit(status)


def pytest_sessionfinish(session, exitstatus):
    """End the process as soon as Python has finished, when bpy was imported (by any test).

    The bpy wheel can deadlock in one of its C++ static destructors at process exit (4.5.15:
    ``GlobalState::~GlobalState`` waits on a condition variable its idle file-closing thread still
    holds), after every test has run and the summary is printed: the run would never return.
    The last atexit handler skips the C-level exit handlers and keeps pytest's exit status.
    """
    if "bpy" in sys.modules:
        atexit.register(_end_now, int(exitstatus))
