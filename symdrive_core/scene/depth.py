"""What a pixel of a package's depth map says: a surface at z metres, the sky, or nothing measured.

Depth maps (``cameras[].frames[].depth``) hold OpenCV z-depth in metres. Sources disagree on 0:
a dense map (a renderer's, the demo street's Cycles depth) measures every pixel, so its 0 is where
the ray meets the sky; LiDAR projected into a camera measures a few pixels, so its 0 is "no return
here" and says nothing about the sky. Each camera declares which (``depth_zero``: ``"sky"``, the
default that older packages rely on, or ``"unmeasured"``); NaN always means unmeasured and +inf
always sky. :func:`decode_depth` turns a stored map into that one in-memory form, so readers never
meet the stored meaning of 0.
"""

from __future__ import annotations

import numpy as np

SKY = np.inf
UNMEASURED = np.nan
DEPTH_ZERO = ("sky", "unmeasured")  # what a stored 0 (or negative) depth means, per camera


def decode_depth(stored: np.ndarray, zero: str = "sky") -> np.ndarray:
    """A stored depth map [H, W] as float32 metres with +inf for sky and NaN where nothing was
    measured; ``zero`` is the camera's ``depth_zero``."""
    if zero not in DEPTH_ZERO:
        raise ValueError(f"depth_zero must be one of {DEPTH_ZERO}, got {zero!r}")
    d = np.array(stored, dtype=np.float32)
    empty = ~(d > 0) & ~np.isnan(d)  # 0, negatives and -inf; NaN stays unmeasured
    d[empty] = SKY if zero == "sky" else UNMEASURED
    return d


def measured(depth):
    """Pixels with a surface at a finite positive depth (numpy arrays and torch tensors alike)."""
    return (depth > 0) & (depth < SKY)


def is_sky(depth: np.ndarray) -> np.ndarray:
    return np.isposinf(depth)


def read_depth(manifest, camera, frame: int) -> np.ndarray | None:
    """Frame ``frame`` of ``camera``'s depth map, decoded; None where the package has none."""
    from ..io.images import read_image

    cf = camera.frames[frame]
    if cf.depth is None:
        return None
    return decode_depth(read_image(manifest.resolve(cf.depth), channels=1)[..., 0], camera.depth_zero)
