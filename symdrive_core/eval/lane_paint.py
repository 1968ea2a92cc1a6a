"""Lane IoU without a learned detector: a fixed classical lane-paint segmenter, scored against
the exact lane-marking masks of the Cycles world.

The paper scores far lateral views by lane-marking IoU, because PSNR hardly sees whether a
lane line is continuous. Here the segmenter is a few fixed rules, the same for every image it
is given (raw render, restored view, Cycles image):

1. **Road region**: pixels whose ray meets the road's ground plane (the height of the package's
   ``ground_truth.road`` centre line under the camera) within ``max_range_m``, at most
   ``half road + road_margin_m`` from the centre line. Everything else (kerbs, sidewalks,
   facades, sky) is never paint.
2. **Paint**: inside the region, a pixel whose value ``max(r, g, b)`` exceeds the mean value of
   the road around it (a ``window_px`` square, road pixels only) by ``brighter``, and whose
   saturation is at most ``max_saturation`` (white paint on grey asphalt).
3. **Clean-up**: a paint pixel with no paint among its 8 neighbours is dropped (speckle).

``lane_iou`` is the IoU of that mask with the true lane pixels inside the same road region
(paint beyond ``max_range_m`` counts for no image). The segmenter's IoU on the Cycles image at
the same camera is the ceiling a perfect restoration would reach.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import conventions
from ..metrics import mask_iou
from ..scene.road import Road, project_onto


@dataclass(frozen=True)
class LanePaintConfig:
    """The segmenter's fixed parameters (chosen on the Cycles images of the recorded drive)."""

    max_range_m: float = 40.0  # farther road is left out: a line there is under a pixel wide
    road_margin_m: float = 0.3  # beyond the outermost lanes' edge, each side
    window_px: int = 15  # side of the square over which the local road brightness is averaged
    brighter: float = 0.16  # paint's value above the local road mean (values in [0, 1])
    max_saturation: float = 0.25  # paint is near grey


DEFAULT = LanePaintConfig()


def road_region(K: np.ndarray, camera_to_world: np.ndarray, width: int, height: int, road: Road,
                config: LanePaintConfig = DEFAULT) -> np.ndarray:
    """Boolean [H, W]: pixels that see the road surface (ground plane under the camera) within
    ``max_range_m`` and within the road's lanes plus ``road_margin_m``."""
    c2w = np.asarray(camera_to_world, dtype=np.float64)
    centre = c2w[:3, 3]
    ground_z = float(road.ground_height(centre[None, :2])[0])
    u, v = conventions.pixel_centers(width, height)
    rays_cam = np.linalg.solve(np.asarray(K, dtype=np.float64), np.stack([u, v, np.ones_like(u)]).reshape(3, -1))
    rays = c2w[:3, :3] @ rays_cam  # world directions, [3, H*W]
    region = np.zeros(width * height, dtype=bool)
    down = rays[2] < -1e-9
    t = np.full(rays.shape[1], np.inf)
    t[down] = (ground_z - centre[2]) / rays[2, down]
    hits = centre[:, None] + rays * np.where(np.isfinite(t), t, 0.0)
    near = down & (t > 0) & (np.linalg.norm(hits[:2] - centre[:2, None], axis=0) <= config.max_range_m)
    if not near.any():
        return region.reshape(height, width)
    line = road.centerline[:, :2]
    seg_near = np.linalg.norm(line - centre[:2], axis=1) <= config.max_range_m + 2.0 * road.lane_width * road.lanes
    keep = np.flatnonzero(seg_near)
    line = line[max(keep.min() - 1, 0):keep.max() + 2] if keep.size else line
    lateral, _, _ = project_onto(line, hits[:2, near].T)
    region[np.flatnonzero(near)] = np.abs(lateral) <= 0.5 * road.lanes * road.lane_width + config.road_margin_m
    return region.reshape(height, width)


def _box_sum(x: np.ndarray, size: int) -> np.ndarray:
    """Sum over a ``size`` x ``size`` window centred on each pixel (zero outside the image)."""
    r = size // 2
    p = np.pad(x, ((r + 1, r), (r + 1, r)))
    c = p.cumsum(0).cumsum(1)
    return c[size:, size:] - c[:-size, size:] - c[size:, :-size] + c[:-size, :-size]


def segment_lane_paint(image: np.ndarray, region: np.ndarray, config: LanePaintConfig = DEFAULT) -> np.ndarray:
    """Boolean [H, W] lane-paint mask of an sRGB image [H, W, 3] in [0, 1] inside ``region``."""
    rgb = np.clip(np.asarray(image, dtype=np.float64)[..., :3], 0.0, 1.0)
    value = rgb.max(axis=2)
    saturation = (value - rgb.min(axis=2)) / np.maximum(value, 1e-6)
    inside = region.astype(np.float64)
    local = _box_sum(value * inside, config.window_px) / np.maximum(_box_sum(inside, config.window_px), 1.0)
    paint = region & (value >= local + config.brighter) & (saturation <= config.max_saturation)
    neighbours = _box_sum(paint.astype(np.float64), 3) - paint
    return paint & (neighbours > 0.5)


@dataclass
class LaneTruth:
    """One view's exact lane mask and road region: scores any image of that view."""

    mask: np.ndarray  # bool [H, W]: the Cycles world's lane pixels inside the region
    region: np.ndarray  # bool [H, W]
    config: LanePaintConfig = DEFAULT

    @classmethod
    def for_camera(cls, mask: np.ndarray, K, camera_to_world, road: Road,
                   config: LanePaintConfig = DEFAULT) -> LaneTruth:
        h, w = mask.shape
        region = road_region(K, camera_to_world, w, h, road, config)
        return cls(mask.astype(bool) & region, region, config)

    def iou(self, image: np.ndarray) -> float:
        """Lane IoU of ``image`` (the segmenter's mask against the truth)."""
        return mask_iou(segment_lane_paint(image, self.region, self.config), self.mask)


def lane_truth(manifest, mask: str, K, camera_to_world) -> LaneTruth:
    """The package's lane mask ``mask`` (relative to it) of the camera (K, camera_to_world), with
    the road region of the package's ``ground_truth.road`` it is scored in."""
    from ..io.images import read_mask
    from ..scene.road import road_from_json

    road = road_from_json(manifest.ground_truth["road"], manifest.path or manifest.root)
    return LaneTruth.for_camera(read_mask(manifest.resolve(mask)) > 0.5, K, camera_to_world, road)
