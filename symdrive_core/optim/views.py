"""The recorded frames a reconstruction trains on, held so a long drive fits in memory, and the
same frames at a coarser resolution for the early iterations of a coarse-to-fine schedule.

A drive of a hundred frames from two cameras at full resolution is gigabytes as float32; its
recorded images are 8-bit, so they are held as the 8-bit levels they are (a quarter of the bytes)
and turned into float32 one view at a time, when a training step or an initialisation reads it.
A coarser level is the area average of the image over ``factor`` x ``factor`` pixel blocks,
computed once when the schedule reaches it and dropped when it moves on (:class:`Levels`), so at
most one level besides the 8-bit images is held at any time.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from ..conventions import scale_intrinsics
from ..errors import InputError
from ..io.images import read_image
from ..scene import Manifest
from ..scene.camera import CameraView
from ..scene.depth import SKY, UNMEASURED, measured, read_depth

EIGHT_BIT_TOLERANCE = 1e-3  # in 8-bit levels: an image this close to whole levels is held as uint8


@dataclass
class View:
    frame: int
    K: torch.Tensor  # [3,3] float32
    viewmat: torch.Tensor  # [4,4] world-to-camera
    pixels: torch.Tensor  # [H,W,3] uint8 (an 8-bit recording), else float32 in [0, 1]
    depth: torch.Tensor | None  # [H,W] metres, +inf = sky, NaN = unmeasured (scene/depth.py)
    width: int
    height: int
    camera_name: str  # the package camera that recorded it

    @property
    def image(self) -> torch.Tensor:
        """[H,W,3] float32 in [0, 1], made from the held pixels at each call."""
        if self.pixels.dtype == torch.uint8:
            return self.pixels.float().div_(255.0)
        return self.pixels

    @property
    def camera(self) -> CameraView:
        """This view's camera (float64 from the stored float32 matrices) for renderers of stored Gaussians."""
        return CameraView(self.viewmat.double().numpy(), self.K.double().numpy(), self.width, self.height)


def held_pixels(image: np.ndarray) -> torch.Tensor:
    """``image`` (float [H,W,3] in [0, 1]) as uint8 where its values are 8-bit levels, else as is:
    no precision is lost either way."""
    levels = np.rint(image * 255.0)
    if np.abs(image * 255.0 - levels).max(initial=0.0) < EIGHT_BIT_TOLERANCE:
        return torch.from_numpy(levels.astype(np.uint8))
    return torch.from_numpy(np.ascontiguousarray(image, dtype=np.float32))


def training_cameras(manifest: Manifest) -> list:
    """What a reconstruction trains on: the first camera, and each other camera that recorded an
    image at every frame (one with none, such as a rendered viewpoint, or with gaps has nothing
    the drive's split can hold out alike)."""
    first, *others = manifest.cameras
    return [first] + [c for c in others if all(cf.image for cf in c.frames)]


def cameras_left_out(manifest: Manifest) -> dict[str, str]:
    """Why each camera :func:`training_cameras` leaves out does not train, by name (said in the
    reconstruction's metrics, not dropped silently)."""
    out = {}
    for c in manifest.cameras[1:]:
        missing = [i for i, cf in enumerate(c.frames) if not cf.image]
        if missing:
            out[c.name] = ("no images" if len(missing) == len(c.frames)
                           else f"no image at frame {missing[0]} ({len(missing)} of {len(c.frames)} frames)")
    return out


def load_views(manifest: Manifest, frames: list[int], camera: str | None = None, depth: bool = True) -> list[View]:
    """The recorded views of ``frames``, frame by frame: of ``camera``, else of every camera that
    recorded images (:func:`training_cameras`; each must have an image at each frame)."""
    cams = [manifest.camera(camera)] if camera else training_cameras(manifest)
    views = []
    for i in frames:
        for cam in cams:
            cf = cam.frames[i]
            if cf.image is None:
                raise InputError(manifest.path or manifest.root, "frame has no image to train on",
                                 f"cameras.{cam.name}.frames[{i}].image")
            img = held_pixels(read_image(manifest.resolve(cf.image), channels=3))
            d = read_depth(manifest, cam, i) if depth else None
            if d is not None:
                d = torch.from_numpy(d)
            views.append(View(i, torch.tensor(cf.K, dtype=torch.float32),
                              torch.tensor(cf.world_to_camera, dtype=torch.float32), img, d, cam.width, cam.height,
                              cam.name))
    return views


def _blocks(t: torch.Tensor, factor: int) -> torch.Tensor:
    """[h, w, factor * factor, ...]: the ``factor`` x ``factor`` pixel blocks of ``t`` [H, W, ...],
    the last ``H % factor`` rows and ``W % factor`` columns left out."""
    h, w = t.shape[0] // factor, t.shape[1] // factor
    rest = t.shape[2:]
    b = t[: h * factor, : w * factor].reshape(h, factor, w, factor, *rest).transpose(1, 2)
    return b.reshape(h, w, factor * factor, *rest)


def block_depth(depth: torch.Tensor, factor: int) -> torch.Tensor:
    """A depth map at 1/``factor`` resolution: a block's mean measured depth where it measured a
    surface and saw no sky, sky where it is all sky, unmeasured elsewhere (a silhouette against the
    sky has no one depth)."""
    b = _blocks(depth, factor)
    hit = measured(b)
    mean = torch.where(hit, b, torch.zeros(())).sum(-1) / hit.sum(-1).clamp_min(1)
    sky = torch.isposinf(b)
    out = torch.full(mean.shape, UNMEASURED, dtype=depth.dtype)
    out = torch.where(hit.any(-1) & ~sky.any(-1), mean, out)
    return torch.where(sky.all(-1), torch.full_like(out, SKY), out)


def downscaled(view: View, factor: int) -> View:
    """``view`` at 1/``factor`` resolution: the area average of its image over ``factor`` x
    ``factor`` blocks (a remainder at the right and bottom edges is cropped, which leaves the
    principal point where it is) and K scaled by 1/``factor`` (pixel edges at integers, so every
    coordinate scales: ``conventions.scale_intrinsics``)."""
    if factor == 1:
        return view
    image = _blocks(view.image, factor).mean(2)
    depth = None if view.depth is None else block_depth(view.depth, factor)
    K = torch.tensor(scale_intrinsics(view.K.double().numpy(), 1.0 / factor), dtype=torch.float32)
    return View(view.frame, K, view.viewmat, image, depth, view.width // factor, view.height // factor,
                view.camera_name)


class Levels:
    """The training views at the downscale a schedule asks for: the held views at 1, else one
    coarser level computed when first asked for and kept until another is asked for."""

    def __init__(self, views: list[View]):
        self.views = views
        self.factor = 1
        self.current = views

    def at(self, factor: int) -> list[View]:
        if factor != self.factor:
            self.current = self.views if factor == 1 else [downscaled(v, factor) for v in self.views]
            self.factor = factor
        return self.current

