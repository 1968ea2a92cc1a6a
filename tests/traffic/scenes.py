"""Small scene packages and vehicle asset folders for the traffic tests, made on the spot."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from symdrive_core.io.ply import write_splats
from tests.conftest import manifest_dict, random_gaussians

CAR = (1.8, 4.5, 1.5)
VAN = (2.0, 5.2, 1.9)


def write_asset(folder: Path, wlh, seed: int = 0) -> Path:
    folder.mkdir(parents=True)
    (folder / "wlh.json").write_text(json.dumps({"wlh": list(wlh), "splats": "splats.ply"}))
    write_splats(folder / "splats.ply", random_gaussians(20, 0, seed))
    return folder


def write_pool(root: Path, sizes=(CAR, VAN)) -> Path:
    for k, wlh in enumerate(sizes):
        write_asset(root / f"vehicle{k}", wlh, k)
    return root


def write_package(root: Path, n_frames: int = 30, road: dict | None = None) -> Path:
    """A package whose frames are 0.1 s apart, with ``road`` in its ground truth (if given)."""
    root.mkdir(parents=True)
    d = manifest_dict(n_frames=n_frames, actors=())
    if road is not None:
        d["ground_truth"] = {"road": road}
    write_splats(root / d["background"]["splats"], random_gaussians(30, 0, 1))
    (root / "manifest.json").write_text(json.dumps(d))
    return root


def curved_road(origin=(0.0, 0.0), length=240.0, amplitude=3.0, period=160.0, lanes=2) -> dict:
    """A gently curving, slightly sloped road along +X starting at ``origin``."""
    x = np.arange(0.0, length + 1e-9, 2.0)
    pts = np.stack([origin[0] + x, origin[1] + amplitude * np.sin(2 * np.pi * x / period), 0.02 * x], axis=1)
    return {"centerline": pts.tolist(), "lanes": lanes, "lane_width": 3.5}
