"""COLMAP's OPENCV lens model in float64 numpy, and images rendered through it by inverse mapping,
for the undistortion tests (an independent implementation: nothing here calls COLMAP)."""

from __future__ import annotations

import numpy as np


def distort(x: np.ndarray, y: np.ndarray, k1: float, k2: float, p1: float, p2: float):
    """Normalised ideal coordinates -> normalised distorted ones (COLMAP's OpenCVCameraModel)."""
    r2 = x * x + y * y
    radial = k1 * r2 + k2 * r2 * r2
    dx = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    dy = y * radial + 2 * p2 * x * y + p1 * (r2 + 2 * y * y)
    return x + dx, y + dy


def undistort(xd: np.ndarray, yd: np.ndarray, *coeffs: float, iterations: int = 100):
    """The ideal coordinates that ``distort`` maps to (xd, yd), by fixed-point iteration; checked."""
    x, y = xd.copy(), yd.copy()
    for _ in range(iterations):
        fx, fy = distort(x, y, *coeffs)
        x, y = x - (fx - xd), y - (fy - yd)
    fx, fy = distort(x, y, *coeffs)
    assert max(np.abs(fx - xd).max(), np.abs(fy - yd).max()) < 1e-10, "inversion did not converge"
    return x, y


def ideal_coords(width: int, height: int, params) -> tuple[np.ndarray, np.ndarray]:
    """Normalised ideal coordinates seen by each pixel centre (+0.5) of an OPENCV camera's image."""
    fx, fy, cx, cy, *coeffs = params
    u, v = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    return undistort((u - cx) / fx, (v - cy) / fy, *coeffs)


def bilinear(image: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``image`` [H, W, C] at continuous pixel coordinates (pixel centres at +0.5), edges clamped."""
    h, w = image.shape[:2]
    x = np.clip(u - 0.5, 0, w - 1)
    y = np.clip(v - 0.5, 0, h - 1)
    x0 = np.minimum(np.floor(x).astype(int), w - 2)
    y0 = np.minimum(np.floor(y).astype(int), h - 2)
    ax, ay = (x - x0)[..., None], (y - y0)[..., None]
    top = image[y0, x0] * (1 - ax) + image[y0, x0 + 1] * ax
    bottom = image[y0 + 1, x0] * (1 - ax) + image[y0 + 1, x0 + 1] * ax
    return top * (1 - ay) + bottom * ay


def distort_image(image: np.ndarray, K: np.ndarray, params) -> np.ndarray:
    """What an OPENCV camera with ``params`` sees of a scene a pinhole ``K`` camera imaged as ``image``."""
    h, w = image.shape[:2]
    x, y = ideal_coords(w, h, params)
    return bilinear(image, K[0, 0] * x + K[0, 2], K[1, 1] * y + K[1, 2])
