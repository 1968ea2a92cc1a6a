"""OpenCV intrinsics K -> Blender camera settings (the inverse of ``conventions.blender_intrinsics``).

numpy only. Blender has one resolution per scene and square-or-wider pixel aspect values
(each >= 1), so unequal fx and fy become a pixel aspect and the sensor is fitted horizontally.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SENSOR_WIDTH_MM = 36.0


@dataclass(frozen=True)
class BlenderLens:
    lens_mm: float
    sensor_width_mm: float
    sensor_fit: str
    shift_x: float
    shift_y: float
    pixel_aspect_x: float
    pixel_aspect_y: float


def lens_from_intrinsics(K, width: int, height: int, sensor_width_mm: float = SENSOR_WIDTH_MM) -> BlenderLens:
    K = np.asarray(K, dtype=np.float64)
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    if fx <= 0 or fy <= 0:
        raise ValueError(f"focal lengths must be positive, got fx={fx}, fy={fy}")
    if abs(K[0, 1]) > 1e-9 * fx:
        raise ValueError(f"skewed intrinsics (K[0][1] = {K[0, 1]}) have no Blender equivalent")
    pax, pay = (1.0, fx / fy) if fx >= fy else (fy / fx, 1.0)
    view = width * pax  # horizontal sensor fit, in aspect-corrected pixels
    return BlenderLens(
        lens_mm=float(fx * sensor_width_mm / width),
        sensor_width_mm=float(sensor_width_mm),
        sensor_fit="HORIZONTAL",
        shift_x=float((width / 2.0 - cx) * pax / view),
        shift_y=float((cy - height / 2.0) * pay / view),
        pixel_aspect_x=float(pax),
        pixel_aspect_y=float(pay),
    )


def parse_offsets(text: str) -> list[float]:
    """``"-1.5, 1.5"`` -> ``[-1.5, 1.5]``; raises ValueError naming the bad item."""
    out = []
    for item in text.replace(";", ",").split(","):
        item = item.strip()
        if not item:
            continue
        try:
            value = float(item)
        except ValueError:
            raise ValueError(f"lateral offsets: {item!r} is not a number") from None
        if not np.isfinite(value):
            raise ValueError(f"lateral offsets: {item!r} is not finite")
        out.append(value)
    return out
