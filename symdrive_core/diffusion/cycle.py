"""Cycle reconstructions: lateral-view degradation seen from the recorded cameras.

The restorer starts sampling from a render at the shifted camera (``N_start``), so at test time
the state it is handed always carries the artifacts of a view the reconstruction was not trained
on. Training pairs ``(I_-d, I_d) -> I_0`` only ever start from the clean recorded image, which
teaches the model to keep whatever the start shows. A cycle reconstruction supplies the missing
input, aligned pixel for pixel with the recorded image: render the reconstruction at every
training camera moved ``delta`` metres sideways, fit a fresh reconstruction to those renders alone
(same initial point cloud and sky, same recipe), and render that one back at the recorded cameras.
What it gets wrong there is what a reconstruction gets wrong ``delta`` metres off its drive.
"""

from __future__ import annotations

import numpy as np
import torch

from .. import conventions
from ..gaussians import Gaussians
from ..optim.densify import DensifyConfig
from ..optim.reconstruct import ReconstructConfig, View, fit, initial_gaussians, load_views
from ..scene import Manifest
from ..splat.render import SplatRenderer
from .config import CycleConfig


def cycle_config(budget: CycleConfig = CycleConfig()) -> ReconstructConfig:
    """The reconstruction recipe with a cycle's budget (shorter than a full reconstruction)."""
    return ReconstructConfig(iters=budget.iters, densify=DensifyConfig(max_gaussians=budget.max_gaussians))


def shifted_views(views: list[View], render: SplatRenderer, offset_m: float) -> list[View]:
    """The recorded views moved ``offset_m`` along their own +x, with ``render``'s images there."""
    out = []
    for v in views:
        camera = v.camera.shifted(offset_m)
        out.append(View(v.frame, v.K, torch.tensor(camera.world_to_camera, dtype=torch.float32),
                        torch.from_numpy(render(camera)), None, v.width, v.height, v.camera_name))
    return out


def cycle_renders(
    manifest: Manifest,
    gaussians: Gaussians,
    offset_m: float,
    frames: list[int],
    cfg: ReconstructConfig,
    *,
    camera: str | None = None,
    progress: bool = True,
) -> np.ndarray:
    """uint8 [F, H, W, 3]: the cycle reconstruction for ``offset_m`` rendered at ``frames``."""
    if offset_m == 0:
        raise ValueError("cycle_renders: the offset must be non-zero (at 0 the cycle is the reconstruction)")
    recorded = load_views(manifest, frames, camera, depth=True)
    render = SplatRenderer(gaussians)
    shifted = shifted_views(recorded, render, offset_m)
    # the recorded views' depth maps seed the sky dome, as in the reconstruction itself; a package
    # without points starts from the reconstruction's own centres
    initial = initial_gaussians(manifest, recorded, cfg, seed=gaussians)
    fitted, _ = fit(shifted, initial, cfg, progress=progress, desc=f"cycle {offset_m:+g} m")
    back = SplatRenderer(fitted)
    return np.stack([conventions.to_uint8(back(v.camera)) for v in recorded])
