"""The lane-paint segmenter and mask IoU on synthetic street images: a painted line on asphalt
is found, noise is not, and the road region is the ground between the road's edges."""

import numpy as np
import pytest

from symdrive_core import conventions
from symdrive_core.eval.lane_paint import LaneTruth, road_region, segment_lane_paint
from symdrive_core.metrics import mask_iou
from symdrive_core.scene.road import Road

W, H = 160, 96
K = conventions.intrinsics_from_fov(W, H, np.deg2rad(70.0))
ROAD = Road(np.array([[-50.0, 0.0, 0.0], [200.0, 0.0, 0.0]]), lanes=2, lane_width=3.5)


def _camera(y: float = -1.75, pitch_deg: float = 3.0) -> np.ndarray:
    """OpenCV camera-to-world 1.6 m above the road at lateral ``y``, looking along +x."""
    p = np.radians(pitch_deg)
    z = np.array([np.cos(p), 0.0, -np.sin(p)])
    x = np.array([0.0, -1.0, 0.0])
    c2w = np.eye(4)
    c2w[:3, 0], c2w[:3, 1], c2w[:3, 2], c2w[:3, 3] = x, np.cross(z, x), z, (0.0, y, 1.6)
    return c2w


def _ground_y(c2w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World y where each pixel centre's ray meets z = 0, and whether it does within 40 m."""
    u, v = conventions.pixel_centers(W, H)
    rays = c2w[:3, :3] @ np.linalg.solve(K, np.stack([u, v, np.ones_like(u)]).reshape(3, -1))
    t = np.where(rays[2] < 0, -c2w[2, 3] / np.minimum(rays[2], -1e-9), np.inf)
    hit = np.isfinite(t) & (t * np.linalg.norm(rays[:2], axis=0) < 40.0)
    y = c2w[1, 3] + t * rays[1]
    return y.reshape(H, W), hit.reshape(H, W)


def _street(c2w, rng, lines=(0.0, -3.5), paint_width=0.3):
    """(image, truth): grey asphalt with slight noise, white lines at the lateral ``lines``."""
    y, ground = _ground_y(c2w)
    truth = ground & np.any([np.abs(y - c) <= paint_width / 2 for c in lines], axis=0) if lines else ground & False
    img = np.empty((H, W, 3))
    img[:] = (0.45, 0.6, 0.85)  # sky
    img[ground] = 0.28 + 0.02 * rng.standard_normal((int(ground.sum()), 1))
    img[truth] = (0.85, 0.85, 0.82)
    return np.clip(img, 0, 1), truth


def test_mask_iou_edge_cases():
    a = np.zeros((4, 5), bool)
    assert mask_iou(a, a) == 1.0  # nothing to find, nothing found
    b = a.copy()
    b[1, 1:3] = True
    assert mask_iou(a, b) == 0.0 and mask_iou(b, a) == 0.0
    c = b.copy()
    c[2, 2] = True
    assert mask_iou(b, c) == pytest.approx(2 / 3)
    with pytest.raises(ValueError, match="shapes differ"):
        mask_iou(a, np.zeros((5, 4), bool))


def test_road_region_is_the_ground_between_the_road_edges():
    c2w = _camera()
    region = road_region(K, c2w, W, H, ROAD)
    y, ground = _ground_y(c2w)
    assert not region[: int(K[1, 2]) - 2].any()  # nothing above the horizon
    inside = ground & (np.abs(y) < 3.5 + 0.3 - 0.05)
    outside = ground & (np.abs(y) > 3.5 + 0.3 + 0.05)
    assert region[inside].mean() > 0.97 and not region[outside].any()


def test_a_painted_line_on_asphalt_is_found():
    rng = np.random.default_rng(0)
    c2w = _camera()
    img, truth = _street(c2w, rng)
    lanes = LaneTruth.for_camera(truth, K, c2w, ROAD)
    assert lanes.mask.sum() > 200
    assert lanes.iou(img) > 0.9


def test_noise_and_plain_asphalt_find_no_lane():
    rng = np.random.default_rng(1)
    c2w = _camera()
    _, truth = _street(c2w, rng)
    lanes = LaneTruth.for_camera(truth, K, c2w, ROAD)
    assert lanes.iou(rng.uniform(0, 1, (H, W, 3))) < 0.1
    plain, _ = _street(c2w, rng, lines=())
    assert not segment_lane_paint(plain, lanes.region).any()
    assert lanes.iou(plain) == 0.0


def test_a_blurred_line_scores_lower_than_a_sharp_one():
    """The metric sees what PSNR hardly does: a line smeared into the asphalt is lost."""
    rng = np.random.default_rng(2)
    c2w = _camera()
    img, truth = _street(c2w, rng)
    lanes = LaneTruth.for_camera(truth, K, c2w, ROAD)
    blurred = img.copy()
    for _ in range(3):  # a 3x3 box blur, three times
        p = np.pad(blurred, ((1, 1), (1, 1), (0, 0)), mode="edge")
        blurred = sum(p[i:i + H, j:j + W] for i in range(3) for j in range(3)) / 9.0
    assert lanes.iou(blurred) < lanes.iou(img) - 0.1
