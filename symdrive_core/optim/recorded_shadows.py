"""Recorded vehicles' sun shadows fitted with the background, as layers that move with them.

Where the scene has a sun (``effects.casting_sun``), a recorded car darkens the road it passes. A
background fitted to the drive as recorded learns that darkening as the road's colour, and the
shadow stays on the street when the car is removed or moved. So a decomposed fit gives each
recorded vehicle a shadow layer (:class:`symdrive_core.shadows.layer.ShadowLayer`: an
occlusion grid on the ground in its own frame) and renders each training view as the renderers
do afterwards: the background and the vehicles at their poses, each layer laid on the background
at the scene's shadow ratio (:func:`symdrive_core.shadows.cast.shaded`). The layers'
logits are fitted with the Gaussians (Adam), so the darkening that moves with a car is learnt as
its shadow, and the background behind it as the road in sunlight.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from ..gaussians import logit
from ..scene import Manifest
from ..scene.poses import Pose
from ..shadows.cast import occlusion_image, shaded, union
from ..shadows.layer import ShadowLayer
from .param_state import SideParameters


@dataclass
class LearntLayer:
    """One vehicle's layer in a fit: its grid's placement and the logits being fitted."""

    grid: ShadowLayer
    logits: torch.nn.Parameter

    def occlusion(self) -> torch.Tensor:
        return torch.sigmoid(self.logits)

    def layer(self) -> ShadowLayer:
        """The layer as it stands."""
        return ShadowLayer(self.occlusion().detach().numpy().astype(np.float32), self.grid.origin, self.grid.cell)


class RecordedShadows(SideParameters):
    """The sun, the shade, and the shadow layers of one decomposed fit's vehicles."""

    checkpoint_file = "shadows.safetensors"

    def __init__(self, sun: np.ndarray, ratio: float, layers: dict[str, LearntLayer], lr: float):
        self.sun, self.ratio, self.layers = sun, ratio, layers
        self.opt = torch.optim.Adam([v.logits for v in layers.values()], lr=lr, eps=1e-15) if layers else None

    @staticmethod
    def of(manifest: Manifest, tracks: list, lr: float) -> RecordedShadows | None:
        """Layers for the recorded vehicles ``tracks`` (:class:`.decompose.Track`), each started as
        its box's shadow at its first pose; None where the scene casts no shadow."""
        sun, _ = manifest.effects.casting_sun()
        if sun is None or not tracks:
            return None
        layers = {}
        for t in tracks:
            grid = ShadowLayer.initial(t.wlh, sun, t.poses[t.frames()[0]])
            layers[t.actor_id] = LearntLayer(grid, torch.nn.Parameter(torch.from_numpy(logit(grid.occlusion))))
        return RecordedShadows(sun, manifest.effects.shade, layers, lr)

    def apply(self, rgb: torch.Tensor, info: dict, view, present: list) -> torch.Tensor:
        """``rgb`` [H, W, 3] (the composed render of ``view``) with the layers of the ``present``
        vehicles (parts with a box) laid where the vehicles do not cover the image; in the graph of
        ``rgb`` and of the layers."""
        vehicles = [p for p in present if p.name in self.layers]
        if not vehicles:
            return rgb
        c2w = np.linalg.inv(view.viewmat.double().numpy())
        K = view.K.double().numpy()
        depth = info["depth"].detach().reshape(view.height, view.width).double().numpy()
        occs = []
        for part in vehicles:
            learnt = self.layers[part.name]
            smap = learnt.grid.at(_pose(part, view.frame), _wlh(part.half), learnt.occlusion())
            occs.append(occlusion_image(smap, c2w, K, view.width, view.height, depth))
        occ = union(occs).to(rgb.dtype)
        covered = 1.0 - torch.prod(1.0 - info["instance"].detach().clamp(0.0, 1.0), dim=-1, keepdim=True)
        return rgb + (1.0 - covered) * (shaded(rgb, occ, self.ratio) - rgb)

    def fitted(self) -> dict[str, ShadowLayer]:
        """Each vehicle's layer as it stands, by actor id."""
        return {name: learnt.layer() for name, learnt in self.layers.items()}

    def params(self) -> dict[str, torch.nn.Parameter]:
        return {name: learnt.logits for name, learnt in self.layers.items()}


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
