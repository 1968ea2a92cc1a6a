"""Training pairs built exactly as the paper builds them, and batches drawn from them.

For a recorded frame at camera C_0, the reconstruction is rendered at C_-d and C_d (the camera
moved d metres left / right along its own x axis); the sample is ``(I_-d, I_d) -> I_0`` with
I_0 the recorded image. The degradation the model learns to undo is therefore exactly the one
lateral novel views suffer, with no hand-made masks or perturbations.

Optionally each recorded frame also gets *degraded starts*: renders of cycle reconstructions
(:mod:`.cycle`) at the recorded camera, which carry the artifacts of a lateral view while staying
aligned with I_0. Training then sometimes starts the noisy state from one of them instead of from
I_0, as sampling does from the render at the shifted camera.

Pairs are stored as one safetensors file of uint8 images ([N, H, W, 3] ``left``, ``target``,
``right``) with ``offset`` and ``frame`` per sample, plus ``degraded`` [M, H, W, 3] with
``degraded_frame`` and ``degraded_offset`` when there are cycles; its SHA-256 identifies the
training data. With ``warps`` each recorded frame also gets its geometry-guided warp
(:mod:`.warp`) at the recorded camera, ``warp`` [F, H, W, 3] with ``warp_mask`` [F, H, W] and
``warp_frame``, made from the other pair frames only: the target never contributes its own image
(or the network would learn to copy it), and frames outside the pairs (held out) are no source.
Batches then also carry that warp as a condition, filled where no frame saw the ground by a
degraded start, as sampling fills it with the render. Batches are random crops (the UNet is fully
convolutional) with a mirror augmentation that flips the images and swaps left and right, which
is the same street seen in a mirror.
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
from ..scene.camera import CameraView
from ..splat.render import SplatRenderer
from .sensor_pairs import sensor_pairs, sensor_views


def make_pairs(
    manifest: Manifest,
    gaussians: Gaussians,
    offsets,
    out: str | os.PathLike,
    *,
    frames: list[int] | None = None,
    camera: str | None = None,
    cycle_offsets=(),
    cycle_config=None,
    warps: bool = False,
    sensor: bool = False,
    drive: dict | None = None,
    progress: bool = True,
) -> Path:
    """Write ``(I_-d, I_d) -> I_0`` for every recorded frame (default: the training frames) and d,
    and the degraded starts of one cycle reconstruction per ``cycle_offsets`` entry (fitted with
    ``cycle_config``, a :class:`~symdrive_core.optim.reconstruct.ReconstructConfig`; default
    :func:`.cycle.cycle_config`); ``warps``: each frame's warp from the other frames (see above);
    ``sensor``: also the pairs whose target a rig's second camera recorded at these frames
    (:mod:`.sensor_pairs`; they need cycle offsets, as every pair with a start does).
    ``drive`` (:func:`.adapt.drive_identity`) is recorded, and passed on to weights trained on them."""
    from safetensors.numpy import save_file
    from tqdm import tqdm

    from ..scene.ground_truth import split_frames

    offsets = [float(d) for d in offsets]
    if not offsets or any(d <= 0 for d in offsets):
        raise ValueError(f"make_pairs: offsets must be positive distances in metres, got {offsets}")
    cycle_offsets = [float(d) for d in cycle_offsets]
    if any(d == 0 for d in cycle_offsets):
        raise ValueError(f"make_pairs: cycle offsets must be non-zero metres, got {cycle_offsets}")
    if warps and not cycle_offsets:
        raise ValueError("make_pairs: warps need cycle offsets (their degraded starts fill what no frame saw)")
    if sensor and not cycle_offsets:
        raise ValueError("make_pairs: sensor pairs need cycle offsets (the synthetic pairs' degraded starts)")
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
        gt = conventions.to_uint8(read_image(manifest.resolve(cf.image), channels=3))
        view = CameraView.of_frame(cam, i)
        for d in offsets:
            left.append(conventions.to_uint8(render(view.shifted(-d))))
            right.append(conventions.to_uint8(render(view.shifted(d))))
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
    if cycle_offsets:
        from .cycle import cycle_config as default_cycle_config
        from .cycle import cycle_renders

        cfg = cycle_config or default_cycle_config()
        degraded = [cycle_renders(manifest, gaussians, d, frames, cfg, camera=cam.name, progress=progress)
                    for d in cycle_offsets]
        tensors["degraded"] = np.concatenate(degraded)
        tensors["degraded_frame"] = np.tile(np.asarray(frames, np.int32), len(cycle_offsets))
        tensors["degraded_offset"] = np.repeat(np.asarray(cycle_offsets, np.float32), len(frames))
    warper = pair_warper(manifest, gaussians, cam, frames) if warps else None
    if warps:
        image, mask = pair_warps(warper, cam, frames, render)
        tensors |= {"warp": conventions.to_uint8(image), "warp_mask": mask.astype(np.uint8),
                    "warp_frame": np.asarray(frames, np.int32)}
    views = sensor_views(manifest, cam.name, frames) if sensor else []
    if views:
        tensors |= sensor_pairs(manifest, views, offsets, render, warper, progress=progress)
    meta = {
        "scene": manifest.name,
        "camera": cam.name,
        "offsets": json.dumps(offsets),
        "frames": json.dumps(frames),
        "gaussians": str(len(gaussians)),
        "cycle_offsets": json.dumps(cycle_offsets),
    }
    if cycle_offsets:
        meta["cycle_iters"] = str(cfg.iters)
    if drive is not None:
        meta["drive"] = json.dumps(drive)
    out = Path(out)
    with atomic_path(out) as tmp:
        save_file(tensors, str(tmp), metadata=meta)
    return out


def pair_warper(manifest: Manifest, gaussians: Gaussians, cam, frames: list[int]):
    """The package's warper for ``cam`` with only the pair ``frames`` as sources (held-out frames
    are no source)."""
    from .warp import package_warper

    warper = package_warper(manifest, cam, gaussians)
    warper.sources = {s: src for s, src in warper.sources.items() if s in set(frames)}
    return warper


def pair_warps(warper, cam, frames: list[int], render: SplatRenderer):
    """The warps [F, H, W, 3] (0 where unseen) and masks [F, H, W] of ``frames`` at their recorded
    cameras, computed as sampling computes them at a shifted camera (rendered depth for the
    occluder test) but with only the other ``frames`` as sources."""
    images, masks = [], []
    for i in frames:
        cf = cam.frames[i]
        depth = render.depth(CameraView.of_frame(cam, i), warper.config.min_alpha)
        w = warper.warp(i, cf.K, cf.camera_to_world, cam.width, cam.height,
                        np.zeros((cam.height, cam.width, 3), np.float32), depth)
        images.append(w.image)
        masks.append(w.mask)
    return np.stack(images), np.stack(masks)


def file_sha256(path: str | os.PathLike) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _check_shapes(path: Path, data: dict) -> None:
    """Images as make-pairs writes them: [N, H, W, 3] uint8, one size throughout, one per pair
    (and per listed frame for degraded starts and warps)."""
    first = data["left"]
    for key in ("left", "target", "right", "degraded", "warp", "sensor_left", "sensor_target", "sensor_right",
                "sensor_start", "sensor_warp"):
        if key not in data:
            continue
        a = data[key]
        if a.dtype != np.uint8 or a.ndim != 4 or a.shape[3] != 3 or a.shape[1:] != first.shape[1:]:
            raise InputError(path, f"expected [N, {first.shape[1]}, {first.shape[2]}, 3] 8-bit images like 'left', "
                                   f"got {a.dtype} {list(a.shape)}", key)
    n = len(first)
    for key in ("target", "right", "offset", "frame"):
        if key in data and len(data[key]) != n:
            raise InputError(path, f"expected one per pair ({n}), got {len(data[key])}", key)
    for key, of in (("degraded_frame", "degraded"), ("warp_frame", "warp"), ("warp_mask", "warp")):
        if of in data and (key not in data or len(data[key]) != len(data[of])):
            raise InputError(path, f"expected one per {of!r} image ({len(data[of])})", key)


class PairSet:
    """The pairs of one file as float tensors [N, 3, H, W] in [0, 1]; with ``holdout`` (recorded
    frames), only the pairs of the other frames, or with ``held_out`` only theirs (degraded starts
    and warps of every frame stay: they are indexed per pair). ``warps=False`` leaves a file's
    warps unread: an unguided restorer then starts from the cycle renders, as it was trained to."""

    def __init__(self, path: str | os.PathLike, holdout=(), *, held_out: bool = False, warps: bool = True):
        from ..io.tensor_file import read_tensor_file

        path = Path(path)
        if not path.exists():
            raise InputError(path, "pairs file not found (write one with `symdrive make-pairs`)")
        data, self.metadata = read_tensor_file(path, "a pairs file", "np")
        missing = {"left", "target", "right"} - set(data)
        if missing:
            raise InputError(path, f"not a pairs file: no {', '.join(sorted(missing))}")
        _check_shapes(path, data)

        def images(key):
            return torch.from_numpy(data[key]).permute(0, 3, 1, 2).float().div_(255.0)

        self.left, self.target, self.right = images("left"), images("target"), images("right")
        self.offset = torch.from_numpy(data.get("offset", np.zeros(len(self.left), np.float32)))
        self.path = path
        self.from_sensor = torch.zeros(len(self.left), dtype=torch.bool)  # per pair: a rig camera's target
        # per pair, the indices of the degraded starts of its recorded frame (empty: none)
        self.degraded = images("degraded") if "degraded" in data else None
        frame = data.get("frame", np.arange(len(self.left), dtype=np.int32))
        by_frame: dict[int, list[int]] = {}
        for k, f in enumerate(data.get("degraded_frame", np.zeros(0, np.int32)).tolist()):
            by_frame.setdefault(int(f), []).append(k)
        self.starts = [by_frame.get(int(f), []) for f in frame.tolist()]
        if self.degraded is not None and not all(self.starts):
            raise InputError(path, "degraded starts do not cover every pair's frame", "degraded_frame")
        # per pair, the index of its frame's warp (None: the file has no warps)
        self.warp = self.warp_mask = self.warp_of = None
        if warps and "warp" in data:
            if self.degraded is None:
                raise InputError(path, "warps need degraded starts to fill what no frame saw", "warp")
            self.warp = images("warp")
            self.warp_mask = torch.from_numpy(data["warp_mask"]).float()[:, None]
            where = {int(f): k for k, f in enumerate(data["warp_frame"].tolist())}
            self.warp_of = [where[int(f)] for f in frame.tolist()]
        if "sensor_left" in data:
            frame = self._add_sensor_pairs(data, images, frame)
        holdout = {int(f) for f in holdout}
        if holdout or held_out:
            keep = [i for i, f in enumerate(frame.tolist()) if (int(f) in holdout) == held_out]
            self.left, self.target, self.right, self.offset, self.from_sensor = (
                x[keep] for x in (self.left, self.target, self.right, self.offset, self.from_sensor))
            self.starts = [self.starts[i] for i in keep]
            self.warp_of = None if self.warp_of is None else [self.warp_of[i] for i in keep]

    def _add_sensor_pairs(self, data: dict, images, frame: np.ndarray) -> np.ndarray:
        """Append the pairs a rig's second camera recorded (:mod:`.sensor_pairs`): each starts from
        the render at its own camera and takes its own warp. Returns every pair's frame."""
        if self.degraded is None:
            raise InputError(self.path, "sensor pairs need the synthetic pairs' degraded starts", "sensor_start")
        if self.warp is not None and "sensor_warp" not in data:
            raise InputError(self.path, "a pairs file with warps needs its sensor pairs' warps too", "sensor_warp")
        view = data["sensor_view"].tolist()
        self.left, self.target, self.right = (torch.cat([x, images(f"sensor_{k}")])
                                              for x, k in ((self.left, "left"), (self.target, "target"),
                                                           (self.right, "right")))
        self.offset = torch.cat([self.offset, torch.from_numpy(data["sensor_offset"])])
        first = len(self.degraded)
        self.degraded = torch.cat([self.degraded, images("sensor_start")])
        self.starts += [[first + v] for v in view]
        if self.warp is not None:
            first = len(self.warp)
            self.warp = torch.cat([self.warp, images("sensor_warp")])
            self.warp_mask = torch.cat([self.warp_mask, torch.from_numpy(data["sensor_warp_mask"]).float()[:, None]])
            self.warp_of += [first + v for v in view]
        self.from_sensor = torch.cat([self.from_sensor, torch.ones(len(view), dtype=torch.bool)])
        return np.concatenate([frame, data["sensor_frame"]])

    def __len__(self) -> int:
        return len(self.target)

    @property
    def has_degraded(self) -> bool:
        return self.degraded is not None

    @property
    def has_warps(self) -> bool:
        return self.warp is not None

    def filled_warp(self, i: int, start: int) -> tuple[torch.Tensor, torch.Tensor]:
        """Pair ``i``'s warp [3, H, W] filled by degraded start ``start`` where no frame saw the
        ground (as sampling fills it with the render), and the guide [4, H, W]: that and the mask."""
        j = self.warp_of[i]
        mask = self.warp_mask[j]
        filled = torch.where(mask > 0, self.warp[j], self.degraded[start])
        return filled, torch.cat([filled, mask])

    def batch(self, size: int, crop: int, generator: torch.Generator, degraded_fraction: float = 0.0):
        """(left, target, right, start, guide) random crops of ``crop`` px with random mirroring;
        ``start`` is one of the frame's degraded starts for a ``degraded_fraction`` share of the
        batch (when the file has them), else the target itself. With warps, ``guide`` [B, 4, h, w]
        is the frame's warp filled by a degraded start where unseen, and its mask; a degraded
        ``start`` is then that filled warp (as sampling starts from the warp). Else ``guide`` is None."""
        n, _, h, w = self.target.shape
        ch, cw = min(crop, h), min(crop, w)
        idx = torch.randint(0, n, (size,), generator=generator)
        ys = torch.randint(0, h - ch + 1, (size,), generator=generator)
        xs = torch.randint(0, w - cw + 1, (size,), generator=generator)
        flips = torch.rand(size, generator=generator) < 0.5
        use = torch.zeros(size, dtype=torch.bool)
        if self.degraded is not None and degraded_fraction > 0:  # no extra draws otherwise: old runs replay
            use = torch.rand(size, generator=generator) < degraded_fraction
        if self.degraded is not None and (degraded_fraction > 0 or self.has_warps):
            pick = torch.rand(size, generator=generator)
        out = ([], [], [], [], [])
        for k in range(size):
            i, y, x = int(idx[k]), int(ys[k]), int(xs[k])
            views = [v[i] for v in (self.left, self.target, self.right)]
            if use[k] or self.has_warps:
                choices = self.starts[i]
                start = choices[int(pick[k] * len(choices))]
            if self.has_warps:
                filled, guide = self.filled_warp(i, start)
                views += [filled if use[k] else views[1], guide]
            else:
                views.append(self.degraded[start] if use[k] else views[1])
            views = [v[:, y : y + ch, x : x + cw] for v in views]
            if flips[k]:
                views = [views[2], views[1], views[0], *views[3:]]
                views = [v.flip(-1) for v in views]
            for lst, v in zip(out, views):
                lst.append(v)
        guide = torch.stack(out[4]) if self.has_warps else None
        return (*(torch.stack(v) for v in out[:4]), guide)


class PairFamily:
    """The pairs of several files (a family of streets) drawn as one set. Each sample's file is
    drawn in proportion to the pairs it holds, so every pair is as likely as in one file, and the
    crop is the largest every file's images hold; with one file, batches are exactly its
    :class:`PairSet`'s. The files must agree on degraded starts and warps (a batch mixes them)."""

    def __init__(self, paths, holdout=(), *, warps: bool = True):
        """``holdout``: recorded frames left out of every file; ``warps`` as :class:`PairSet`'s."""
        paths = [Path(p) for p in paths]
        if not paths:
            raise ValueError("PairFamily needs at least one pairs file")
        self.sets = [PairSet(p, holdout, warps=warps) for p in paths]
        for kind, what in (("has_degraded", "degraded starts (make-pairs --cycle)"),
                           ("has_warps", "warps (make-pairs --warps)")):
            first = getattr(self.sets[0], kind)
            odd = next((s for s in self.sets if getattr(s, kind) != first), None)
            if odd is not None:
                raise InputError(odd.path, f"{'has no' if first else 'has'} {what}, unlike "
                                           f"{self.sets[0].path.name}: train on pairs files made alike")
        self.from_sensor = torch.cat([s.from_sensor for s in self.sets])

    def __len__(self) -> int:
        return sum(len(s) for s in self.sets)

    @property
    def has_degraded(self) -> bool:
        return self.sets[0].has_degraded

    @property
    def has_warps(self) -> bool:
        return self.sets[0].has_warps

    def batch(self, size: int, crop: int, generator: torch.Generator, degraded_fraction: float = 0.0):
        """As :meth:`PairSet.batch`, each sample from a file drawn by its share of the pairs."""
        if len(self.sets) == 1:
            return self.sets[0].batch(size, crop, generator, degraded_fraction)
        crop = min([crop, *(min(s.target.shape[-2:]) for s in self.sets if len(s))])
        weights = torch.tensor([float(len(s)) for s in self.sets], dtype=torch.float64)
        counts = torch.bincount(torch.multinomial(weights, size, replacement=True, generator=generator),
                                minlength=len(self.sets)).tolist()
        parts = [s.batch(n, crop, generator, degraded_fraction) for s, n in zip(self.sets, counts) if n]
        guides = [p[4] for p in parts]
        return (*(torch.cat([p[k] for p in parts]) for k in range(4)),
                None if guides[0] is None else torch.cat(guides))
