"""Numbers in the text files that come with a recorded drive (calibration, poses, timestamps).

One reader for KITTI's ``calib.txt``, poses and ``times.txt`` and for a LiDAR's sensor-to-camera
transform, so a malformed line is refused the same way everywhere: naming the file and the entry.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError


def finite_numbers(text: str, count: int, path: Path, where: str) -> np.ndarray:
    """The ``count`` finite numbers of ``text`` (separated by spaces or commas), float64; anything
    else is an :class:`InputError` naming ``path`` and ``where``."""
    try:
        v = np.array([float(x) for x in text.replace(",", " ").split()], dtype=np.float64)
    except ValueError:
        raise InputError(path, f"expected {count} numbers", where) from None
    if len(v) != count or not np.isfinite(v).all():
        raise InputError(path, f"expected {count} finite numbers, got {len(v)}", where)
    return v
