"""Recorded vehicles' sun shadows laid on the background while it is fitted.

Where the scene has a sun (``effects.casting_sun``), a recorded car darkens the road it passes. A
background fitted to the drive as recorded learns that darkening as the road's colour, and the
shadow stays on the street when the car is removed or moved. So a decomposed fit renders each
training view as the renderers do afterwards: the background and the recorded vehicles at their
poses, with each vehicle's shadow (from its own Gaussians as they stand,
:mod:`symdrive_core.insertion.cast_shadow`) laid on the background at the scene's shadow ratio.
The background then learns the road in sunlight; the darkening is the car's, and goes where it
goes.

A shadow map is a rasterization of the vehicle's Gaussians along the sun, so the maps of every
(vehicle, frame) are kept and rebuilt every ``refresh_every`` iterations, as the vehicles' shapes
and poses settle; the pixels' ground points and the depth test (a wall in front of the shadowed
ground stays lit) are evaluated per step against the rendered depth.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch

from ..gaussians import Gaussians
from ..insertion.cast_shadow import ShadowMap, combined_occlusion, shaded, vehicle_shadow_map
from ..scene import Manifest
from ..scene.poses import Pose

MAP_CELL_M = 0.03  # the shadow maps' finest cell while fitting: about a near road pixel of a driving camera


@dataclass
class RecordedShadows:
    """The sun, the shade and the kept shadow maps of one decomposed fit."""

    sun: np.ndarray  # unit direction sunlight travels
    ratio: float  # fraction of its light the ground keeps in full shadow
    refresh_every: int
    maps: dict[tuple[str, int], ShadowMap | None] = field(default_factory=dict)
    shapes: dict[str, Gaussians] = field(default_factory=dict)  # each vehicle's Gaussians as of the refresh
    built_at: int | None = None

    @staticmethod
    def of(manifest: Manifest, refresh_every: int) -> RecordedShadows | None:
        """The scene's shadows to lay, None where it casts none (no sun, or shadows off)."""
        sun, _ = manifest.effects.casting_sun()
        return None if sun is None else RecordedShadows(sun, manifest.effects.shade, refresh_every)

    def apply(self, rgb: torch.Tensor, info: dict, view, present: list, it: int) -> torch.Tensor:
        """``rgb`` [H, W, 3] (the composed render of ``view``) with the shadows of the ``present``
        vehicles (parts with a box) laid where the vehicles do not cover the image; in the graph of
        ``rgb``, so the background behind a shadow is fitted in sunlight."""
        vehicles = [p for p in present if p.half is not None]
        if not vehicles:
            return rgb
        if self.built_at is None or it - self.built_at >= self.refresh_every:
            self.maps.clear()
            self.shapes.clear()
            self.built_at = it
        maps = [m for m in (self._map(p, view.frame) for p in vehicles) if m is not None]
        if not maps:
            return rgb
        c2w = np.linalg.inv(view.viewmat.double().numpy())
        depth = info["depth"].detach().reshape(view.height, view.width).double().numpy()
        occlusion = combined_occlusion(maps, c2w, view.K.double().numpy(), view.width, view.height, depth)
        if not (occlusion > 0).any():
            return rgb
        covered = 1.0 - torch.prod(1.0 - info["instance"].detach().clamp(0.0, 1.0), dim=-1, keepdim=True)
        occ = torch.from_numpy(occlusion).to(rgb.dtype)
        return rgb + (1.0 - covered) * (shaded(rgb, occ, self.ratio) - rgb)

    def _map(self, part, frame: int) -> ShadowMap | None:
        key = (part.name, frame)
        if key not in self.maps:
            if part.name not in self.shapes:
                self.shapes[part.name] = part.gaussians()
            self.maps[key] = vehicle_shadow_map(self.shapes[part.name], _pose(part, frame), _wlh(part.half), self.sun,
                                                min_cell=MAP_CELL_M)
        return self.maps[key]


def _pose(part, frame: int) -> Pose:
    """Where ``part`` stands at ``frame``: its refined pose as it stands, else its recorded one."""
    if part.refine is None:
        return part.poses[frame]
    from ..rotations import matrix_to_quat

    with torch.no_grad():
        R, T = part.refine.pose(frame)
    return Pose(T.double().numpy().copy(), matrix_to_quat(R.double().numpy()))


def _wlh(half: np.ndarray) -> np.ndarray:
    """A box's (width, length, height) from its half extents along (length, width, height)."""
    return 2.0 * np.array([half[1], half[0], half[2]])
