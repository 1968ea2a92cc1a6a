"""Text the add-on's panels take from the user, parsed (numpy only, imports without Blender)."""

from __future__ import annotations

import numpy as np


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
