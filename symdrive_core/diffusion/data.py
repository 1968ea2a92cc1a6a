"""Training pairs built exactly as the paper builds them, and batches drawn from them.

For a recorded frame at camera C_0, the reconstruction is rendered at C_-d and C_d (the camera
moved d metres left / right along its own x axis); the sample is ``(I_-d, I_d) -> I_0`` with
I_0 the recorded image. The degradation the model learns to undo is therefore exactly the one
lateral novel views suffer, with no hand-made masks or perturbations.

Pairs are stored as one safetensors file of uint8 images ([N, H, W, 3] ``left``, ``target``,
``right``) with ``offset`` and ``frame`` per sample; its SHA-256 identifies the training data.
Batches are random crops (the UNet is fully convolutional) with a mirror augmentation that
flips all three images and swaps left and right, which is the same street seen in a mirror.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import numpy as np
import torch

from .. import conventions
from ..errors import InputError
from ..gaussians import Gaussians
from ..io.atomic import atomic_path
from ..io.images import read_image
from ..scene import Manifest


class SplatRenderer:
    """Renders one set of Gaussians at arbitrary cameras ([H, W, 3] float32 in [0, 1])."""

    def __init__(self, gaussians: Gaussians):
        from ..optim.reconstruct import params_from_gaussians

        self.degree = gaussians.sh_degree
        self.params = params_from_gaussians(gaussians, self.degree)

    @torch.no_grad()
    def __call__(self, K, world_to_camera, width: int, height: int) -> np.ndarray:
        from ..optim.reconstruct import render

        rgb, _, _ = render(
            self.params,
            torch.tensor(K, dtype=torch.float32),
            torch.tensor(world_to_camera, dtype=torch.float32),
            width,
            height,
            self.degree,
        )
        return rgb.clamp(0, 1).numpy()

    def shifted(self, K, camera_to_world, offset_m: float, width: int, height: int) -> np.ndarray:
        """The render at the camera moved ``offset_m`` along its own +x (right)."""
        c2w = conventions.lateral_shift(camera_to_world, offset_m)
        return self(K, conventions.invert_rigid(c2w), width, height)


def to_uint8(image: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(np.asarray(image, dtype=np.float32) * 255.0), 0, 255).astype(np.uint8)


def make_pairs(
    manifest: Manifest,
    gaussians: Gaussians,
    offsets,
    out: str | os.PathLike,
    *,
    frames: list[int] | None = None,
    camera: str | None = None,
    progress: bool = True,
) -> Path:
    """Write ``(I_-d, I_d) -> I_0`` for every recorded frame (default: the training frames) and d."""
    from safetensors.numpy import save_file
    from tqdm import tqdm

    from ..world.package import split_frames

    offsets = [float(d) for d in offsets]
    if not offsets or any(d <= 0 for d in offsets):
        raise ValueError(f"make_pairs: offsets must be positive distances in metres, got {offsets}")
    cam = manifest.camera(camera) if camera else manifest.cameras[0]
    frames = split_frames(manifest)[0] if frames is None else list(frames)
    render = SplatRenderer(gaussians)
    left, target, right, offs, idx = [], [], [], [], []
    for i in tqdm(frames, desc="make-pairs", unit="frame", disable=not progress):
        cf = cam.frames[i]
        if cf.image is None:
            raise InputError(
                manifest.path or manifest.root,
                "frame has no recorded image",
                f"cameras.{cam.name}.frames[{i}].image",
            )
        gt = to_uint8(read_image(manifest.resolve(cf.image), channels=3))
        for d in offsets:
            left.append(to_uint8(render.shifted(cf.K, cf.camera_to_world, -d, cam.width, cam.height)))
            right.append(to_uint8(render.shifted(cf.K, cf.camera_to_world, d, cam.width, cam.height)))
            target.append(gt)
            offs.append(d)
            idx.append(i)
    tensors = {
        "left": np.stack(left),
        "target": np.stack(target),
        "right": np.stack(right),
        "offset": np.asarray(offs, np.float32),
        "frame": np.asarray(idx, np.int32),
    }
    meta = {
        "scene": manifest.name,
        "camera": cam.name,
        "offsets": json.dumps(offsets),
        "frames": json.dumps(frames),
        "gaussians": str(len(gaussians)),
    }
    out = Path(out)
    with atomic_path(out) as tmp:
        save_file(tensors, str(tmp), metadata=meta)
    return out


def file_sha256(path: str | os.PathLike) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


class PairSet:
    """The pairs of one file as float tensors [N, 3, H, W] in [0, 1]."""

    def __init__(self, path: str | os.PathLike):
        from safetensors.numpy import load_file

        path = Path(path)
        if not path.exists():
            raise InputError(path, "pairs file not found (write one with `symdrive make-pairs`)")
        data = load_file(str(path))
        from safetensors import safe_open

        with safe_open(str(path), "np") as f:
            self.metadata = dict(f.metadata() or {})
        missing = {"left", "target", "right"} - set(data)
        if missing:
            raise InputError(path, f"not a pairs file: no {', '.join(sorted(missing))}")

        def images(key):
            return torch.from_numpy(data[key]).permute(0, 3, 1, 2).float().div_(255.0)

        self.left, self.target, self.right = images("left"), images("target"), images("right")
        self.offset = torch.from_numpy(data.get("offset", np.zeros(len(self.left), np.float32)))
        self.path = path

    def __len__(self) -> int:
        return len(self.target)

    def batch(self, size: int, crop: int, generator: torch.Generator):
        """(left, target, right) random crops of ``crop`` px with random mirroring."""
        n, _, h, w = self.target.shape
        ch, cw = min(crop, h), min(crop, w)
        idx = torch.randint(0, n, (size,), generator=generator)
        ys = torch.randint(0, h - ch + 1, (size,), generator=generator)
        xs = torch.randint(0, w - cw + 1, (size,), generator=generator)
        flips = torch.rand(size, generator=generator) < 0.5
        out = ([], [], [])
        for k in range(size):
            i, y, x = int(idx[k]), int(ys[k]), int(xs[k])
            views = [v[i, :, y : y + ch, x : x + cw] for v in (self.left, self.target, self.right)]
            if flips[k]:
                views = [v.flip(-1) for v in reversed(views)]
            for lst, v in zip(out, views):
                lst.append(v)
        return tuple(torch.stack(v) for v in out)
