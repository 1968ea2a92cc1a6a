"""Insertion baselines: naive (the render as is) and Reinhard colour statistics transfer.

Reinhard et al. (2001) transfer per-channel mean and standard deviation in lαβ, a decorrelated
log-LMS space where matching channels independently is sound. Here the car's pixels are
matched to a ring of background around it, the classic training-free harmonization baseline.
Images are display-encoded sRGB in [0, 1]; they are linearised before going to LMS.
"""

from __future__ import annotations

import numpy as np

from ..conventions import linear_to_srgb, srgb_to_linear
from ..shadows.region import dilate
from ..splat.constants import ALPHA_THRESHOLD

_RGB_TO_LMS = np.array([[0.3811, 0.5783, 0.0402], [0.1967, 0.7244, 0.0782], [0.0241, 0.1288, 0.8444]])
_LMS_TO_LAB = np.diag([1 / np.sqrt(3), 1 / np.sqrt(6), 1 / np.sqrt(2)]) @ np.array(
    [[1, 1, 1], [1, 1, -2], [1, -1, 0]], dtype=np.float64)
_EPS = 1e-4


def rgb_to_lab(rgb: np.ndarray) -> np.ndarray:
    """sRGB [..., 3] -> Reinhard lαβ."""
    lms = srgb_to_linear(rgb) @ _RGB_TO_LMS.T
    return np.log10(np.clip(lms, _EPS, None)) @ _LMS_TO_LAB.T


def lab_to_rgb(lab: np.ndarray) -> np.ndarray:
    lms = 10.0 ** (np.asarray(lab, dtype=np.float64) @ np.linalg.inv(_LMS_TO_LAB).T)
    return linear_to_srgb(lms @ np.linalg.inv(_RGB_TO_LMS).T)


def background_ring(mask: np.ndarray, width: int = 8, gap: int = 1) -> np.ndarray:
    """Pixels within ``width`` of the mask but not in it (nor ``gap`` pixels from it)."""
    m = np.asarray(mask, dtype=bool)
    return dilate(m, width + gap) & ~dilate(m, gap)


def naive(image: np.ndarray) -> np.ndarray:
    """The inserted render unchanged (the baseline every method must beat)."""
    return np.asarray(image, dtype=np.float32).copy()


def reinhard_transfer(image: np.ndarray, vehicle_alpha: np.ndarray, *, ring: int = 8, threshold: float = 0.5,
                      strength: float = 1.0) -> np.ndarray:
    """Match the car's lαβ mean/std to the surrounding background's; blend by the car's alpha."""
    img = np.asarray(image, dtype=np.float64)
    alpha = np.clip(np.asarray(vehicle_alpha, dtype=np.float64), 0.0, 1.0)
    car = alpha > threshold
    bg = background_ring(car, ring) & (alpha < ALPHA_THRESHOLD)
    if car.sum() < 2 or bg.sum() < 2:
        return img.astype(np.float32)
    lab = rgb_to_lab(img)
    mu_c, sd_c = lab[car].mean(0), lab[car].std(0)
    mu_b, sd_b = lab[bg].mean(0), lab[bg].std(0)
    target = (lab - mu_c) * (sd_b / np.maximum(sd_c, 1e-6)) + mu_b
    moved = lab + strength * (target - lab)
    out = lab_to_rgb(moved)
    a = alpha[..., None]
    return np.clip(a * out + (1.0 - a) * img, 0.0, 1.0).astype(np.float32)
