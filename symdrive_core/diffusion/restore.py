"""Auto-regressive lateral restoration, and the restored views that 3DGS refinement trains on
(its evaluation against ground truth: :mod:`symdrive_core.eval.restoration`).

From the recorded view at C_0 the chain walks outward with step ``d``: the view at ``d`` is
restored from ``(I_0, render(2d))``, the one at ``2d`` from ``(restored I_d, render(3d))``, and
so on; on the left side the roles of the two conditions swap (the model's left input is always
the view further left). A target that is not a multiple of ``d`` is reached in ``ceil(o / d)``
equal steps, none longer than ``d``. The sampler starts at ``N_start`` from the raw render at
the target camera: it is the only input that sits exactly where the output must, which is the
point of the paper's position-accurate initialisation. ``d = 0`` is the paper's single-view
ablation: both conditions are the render at the target itself.

Geometry-guided methods (``geo_single_view``, ``geo_ar_d<step>``) replace every render the chain
uses (the start state and the far condition) by the recorded neighbours warped into that camera
over the ground (:mod:`.warp`), the render kept where no frame sees the ground; ``warp`` is that
image alone, with no restorer. A restorer trained with the warp as a condition (``guide_channels``)
also gets the warp at the target camera and its validity mask; in the unguided methods its guide
is the render with an empty mask (no frame seen). A restorer with a ``guided`` sibling (the shipped
guided weights) hands the geometry-guided samples to it.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import torch

from ..conventions import both_sides
from ..gaussians import Gaussians
from ..io.images import read_image
from ..scene import Manifest
from ..scene.camera import CameraView, SeenBy
from ..scene.ground_truth import truth_camera
from ..splat.render import SplatRenderer
from .sampler import DEFAULT, SamplerConfig, greyed, is_grey, restore_image, to_numpy, to_tensor
from .warp import Warp

WARP = "warp"
GEO = "geo_"


def method_step(method: str) -> float:
    """``single_view`` -> 0; ``ar_d<step>`` -> step in metres; the same with the ``geo_`` prefix."""
    method = method.removeprefix(GEO)
    if method == "single_view":
        return 0.0
    if method.startswith("ar_d"):
        try:
            step = float(method[4:])
        except ValueError:
            step = -1.0
        if step > 0:
            return step
    raise ValueError(f"unknown restoration method {method!r} (expected single_view, ar_d<metres>, {WARP}, "
                     f"or {GEO}single_view, {GEO}ar_d<metres>)")


def needs_warp(methods) -> bool:
    return any(m == WARP or m.startswith(GEO) for m in methods)


def chain_positions(offset: float, step: float) -> list[float]:
    """The offsets the chain visits on its way to ``offset`` (ending there), steps <= ``step``."""
    n = max(1, math.ceil(abs(offset) / step - 1e-9))
    return [offset * k / n for k in range(1, n + 1)]


class LateralChain:
    """Restores the lateral views of one recorded frame; renders and restorations are cached,
    so chains that share a prefix (0.5, 1.0, ... with d = 0.5) are sampled once."""

    def __init__(
        self,
        restorer,
        render: SplatRenderer,
        recorded: np.ndarray,
        camera: CameraView,
        sampler: SamplerConfig = DEFAULT,
        warper=None,
        frame: int | None = None,
    ):
        """``warper`` (a :class:`~.warp.GroundWarper`) and ``frame`` (the recorded frame this
        chain starts from) are needed only by the geometry-guided methods."""
        self.restorer, self.render, self.camera, self.sampler = restorer, render, camera, sampler
        self.recorded = recorded
        # a grey camera: every view of it is grey, whatever colour the reconstruction's renders
        # (fitted from coloured initial points, say) picked up
        self.grey = is_grey(to_tensor(recorded))
        self.warper, self.frame = warper, frame
        self._renders: dict[float, np.ndarray] = {}
        self._warps: dict[float, Warp] = {}
        self._restored: dict[tuple[bool, float, float], np.ndarray] = {}
        self.samples = 0
        self.warp_seconds: list[float] = []  # per warp computed

    @classmethod
    def for_frame(cls, manifest: Manifest, cam, frame: int, restorer, render: SplatRenderer,
                  sampler: SamplerConfig = DEFAULT, warper=None) -> LateralChain:
        """The chain around recorded frame ``frame`` of the package's camera ``cam``; a frame with
        no recorded image starts from the render at its camera."""
        cf = cam.frames[frame]
        recorded = (read_image(manifest.resolve(cf.image), channels=3) if cf.image
                    else render(CameraView.of_frame(cam, frame)))
        return cls(restorer, render, recorded, CameraView.of_frame(cam, frame), sampler, warper, frame)

    def raw(self, offset: float) -> np.ndarray:
        key = round(offset, 6)
        if key not in self._renders:
            v = self.camera.shifted(offset)
            self._renders[key] = self.render(v)
        return self._renders[key]

    def warp(self, offset: float) -> np.ndarray:
        """The recorded neighbours warped to ``offset`` over the ground, the render elsewhere."""
        return self._warp(offset).image

    def _warp(self, offset: float) -> Warp:
        key = round(offset, 6)
        if key not in self._warps:
            if self.warper is None:
                raise ValueError("geometry-guided restoration needs a chain made with a warper")
            t0 = time.perf_counter()
            v = self.camera.shifted(offset)
            depth = self.render.depth(v, self.warper.config.min_alpha)
            self._warps[key] = self.warper.warp(self.frame, v.K, v.camera_to_world, v.width, v.height,
                                                self.raw(offset), depth)
            self.warp_seconds.append(time.perf_counter() - t0)
        return self._warps[key]

    def _start(self, offset: float, guided: bool) -> np.ndarray:
        return self.warp(offset) if guided else self.raw(offset)

    def by_method(self, offset: float, method: str) -> np.ndarray:
        """The view at ``offset`` by a named method (see :func:`method_step` and ``warp``)."""
        if method == WARP:
            return self.recorded if offset == 0 else self.warp(offset)
        return self.restore(offset, method_step(method), guided=method.startswith(GEO))

    def _restorer(self, guided: bool):
        return (getattr(self.restorer, "guided", None) or self.restorer) if guided else self.restorer

    def _guide(self, offset: float, guided: bool) -> torch.Tensor | None:
        """Warp and mask at ``offset`` [1, 4, H, W] for a restorer that takes them, else None."""
        if not getattr(self._restorer(guided), "guide_channels", 0):
            return None
        if guided:
            w = self._warp(offset)
            image, mask = w.image, w.mask
        else:
            image = self.raw(offset)
            mask = np.zeros(image.shape[:2], dtype=bool)
        return torch.cat([to_tensor(image), torch.from_numpy(mask).float()[None, None]], dim=1)

    def _sample(self, left: np.ndarray, right: np.ndarray, init: np.ndarray, offset: float, guided: bool) -> np.ndarray:
        self.samples += 1
        images, guide = [to_tensor(x) for x in (left, right, init)], self._guide(offset, guided)
        if self.grey:
            images = [greyed(x) for x in images]
            guide = None if guide is None else torch.cat([greyed(guide[:, :3]), guide[:, 3:]], dim=1)
        return to_numpy(restore_image(self._restorer(guided), *images, self.sampler, guide))

    def restore(self, offset: float, step: float, guided: bool = False) -> np.ndarray:
        """The restored view at ``offset`` metres (positive = right) with chain step ``step``;
        ``guided``: warps instead of renders as the start state and the far condition."""
        if offset == 0:
            return self.recorded
        if step == 0:
            key = (guided, 0.0, round(offset, 6))
            if key not in self._restored:
                r = self._start(offset, guided)
                self._restored[key] = self._sample(r, r, r, offset, guided)
            return self._restored[key]
        prev, prev_pos = self.recorded, 0.0
        for pos in chain_positions(offset, step):
            key = (guided, step, round(pos, 6))
            if key not in self._restored:
                far = self._start(2 * pos - prev_pos, guided)
                left, right = (prev, far) if pos > 0 else (far, prev)
                self._restored[key] = self._sample(left, right, self._start(pos, guided), pos, guided)
            prev, prev_pos = self._restored[key], pos
        return prev


@dataclass
class RestoredView(SeenBy):
    """A restored image and the camera it belongs to (what 3DGS refinement trains on)."""

    frame: int
    offset_m: float
    camera: CameraView
    image: np.ndarray

    @classmethod
    def shifted(cls, cam, frame: int, offset_m: float, image: np.ndarray) -> RestoredView:
        """``image`` as the view of ``cam``'s recorded frame ``frame`` moved ``offset_m`` to the right."""
        return cls(frame, offset_m, CameraView.of_frame(cam, frame).shifted(offset_m), image)


def restore_lateral_views(
    manifest: Manifest,
    gaussians: Gaussians,
    restorer,
    frames: list[int] | None,
    offsets: list[float],
    step: float,
    *,
    sampler: SamplerConfig = DEFAULT,
    chains: dict[int, LateralChain] | None = None,
    progress: bool = True,
    guided: bool = False,
) -> list[RestoredView]:
    """The views at ``+-offsets`` of each recorded frame in ``frames`` (default: all) of the lateral
    camera, restored by the chain with step ``step`` (``guided``: geometry-guided); ``chains`` (by
    frame) are reused, so views already restored while scoring are not sampled again. Refinement
    trains on these."""
    from tqdm import tqdm

    cam = truth_camera(manifest)
    frames = range(len(cam.frames)) if frames is None else frames
    render = SplatRenderer(gaussians)
    chains = {} if chains is None else chains
    warper = chain_warper(manifest, cam, gaussians) if guided else None
    signed = both_sides(offsets)
    views = []
    for fi in tqdm(frames, desc="restore", unit="frame", disable=not progress):
        if fi not in chains:
            chains[fi] = LateralChain.for_frame(manifest, cam, fi, restorer, render, sampler, warper)
        elif guided and chains[fi].warper is None:
            chains[fi].warper = warper
        views += [RestoredView.shifted(cam, fi, off, chains[fi].restore(off, step, guided)) for off in signed]
    return views


def chain_warper(manifest: Manifest, cam, gaussians: Gaussians):
    """The lateral camera's warper for the geometry-guided chain."""
    from .warp import package_warper

    return package_warper(manifest, cam, gaussians)
