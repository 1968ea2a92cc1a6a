"""A recorded vehicle's shadow as a learnt layer on the ground, in the vehicle's own frame.

A recorded car's Gaussians show what the cameras saw of it: its far side, its roof and the gap
under it are guesses, so the shadow they cast along the sun (:mod:`.cast`) is a patchy
blob where the real one is a crisp silhouette. The shadow the drive recorded is better learnt
from the drive itself: an occlusion grid on the ground plane in the vehicle's frame (x along its
length, y across), around its box by as far as its shadow can reach, fitted with the background
(:mod:`symdrive_core.optim.recorded_shadows`). It starts as the box's own shadow at the sun's
direction; the frames show where it is lighter (windows, the gap under the body) or longer.
Placed at any pose it is a :class:`.cast.ShadowMap`, so every renderer lays it as it lays
an inserted vehicle's: it goes where the car goes, and with it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import conventions
from ..io.shadow_grid import read_shadow_grid, write_shadow_grid
from ..scene import Pose
from .cast import ShadowMap
from .region import inside_convex, shadow_polygon, vehicle_ground_z

LAYER_CELL_M = 0.1
LAYER_MARGIN_M = 0.5  # room beyond the farthest the box's shadow reaches (soft edges, box error)
INITIAL_SHADOW = 0.9  # the start inside the box's shadow: a car blocks the sun (but for its windows)
INITIAL_LIT = 0.02  # the start outside it


@dataclass(frozen=True)
class ShadowLayer:
    occlusion: np.ndarray  # [rows, cols] in [0, 1]: row = local y, col = local x
    origin: np.ndarray  # local (x, y) of the grid's corner
    cell: float

    @staticmethod
    def initial(wlh, sun_direction, pose: Pose) -> ShadowLayer:
        """The box's shadow at ``pose`` (the sun's direction in the vehicle's frame there), drawn
        on a grid that reaches as far as any shadow of the box can."""
        s = conventions.sun_above_horizon(sun_direction)
        if s is None:
            raise ValueError("a shadow layer needs a sun above the horizon")
        w, length, h = (float(v) for v in wlh)
        reach = h * float(np.hypot(s[0], s[1])) / -s[2] + LAYER_MARGIN_M
        half = np.array([length / 2 + reach, w / 2 + reach])
        cols, rows = (int(np.ceil(2 * v / LAYER_CELL_M)) for v in half)
        origin = -0.5 * LAYER_CELL_M * np.array([cols, rows])
        hull = shadow_polygon(Pose(np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0])), wlh, pose.R.T @ s)
        x = origin[0] + LAYER_CELL_M * (np.arange(cols) + 0.5)
        y = origin[1] + LAYER_CELL_M * (np.arange(rows) + 0.5)
        centres = np.stack(np.meshgrid(x, y), -1)
        occlusion = np.where(inside_convex(centres, hull), INITIAL_SHADOW, INITIAL_LIT)
        return ShadowLayer(occlusion.astype(np.float32), origin, LAYER_CELL_M)

    def at(self, pose: Pose, wlh, occlusion=None) -> ShadowMap:
        """The layer on the ground under the vehicle standing at ``pose`` (``occlusion``: a tensor
        of the grid's shape to place instead, as a fit does)."""
        gz = vehicle_ground_z(pose, wlh)
        Rt = pose.R.T
        to_map = np.concatenate([Rt[:2, :2], (Rt[:2, 2] * gz - Rt[:2] @ pose.translation)[:, None]], 1)
        return ShadowMap(self.occlusion if occlusion is None else occlusion, self.origin, self.cell, gz, to_map)

    def save(self, path: Path) -> None:
        write_shadow_grid(path, self.occlusion, self.origin, self.cell)

    @staticmethod
    def load(path: Path) -> ShadowLayer:
        """A layer as :meth:`save` wrote it; a ValueError naming what is wrong otherwise."""
        return ShadowLayer(*read_shadow_grid(path))


def package_layers(manifest) -> dict[str, ShadowLayer]:
    """The shadow layers a package's recorded vehicles name (``assets.shadow``), by actor id."""
    return {a.id: ShadowLayer.load(manifest.resolve(a.shadow)) for a in manifest.actors if a.shadow}
