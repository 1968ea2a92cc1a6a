"""The file of a recorded vehicle's shadow layer: an occlusion grid on the ground in its own frame
(safetensors: the grid, and its corner and cell size as metadata). Read here alone, so the
package check and the renderers agree on what a valid one is."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .atomic import atomic_path


def write_shadow_grid(path: Path, occlusion: np.ndarray, origin: np.ndarray, cell: float) -> None:
    from safetensors.numpy import save_file

    meta = {"origin": json.dumps([float(v) for v in origin]), "cell": repr(float(cell))}
    with atomic_path(Path(path)) as tmp:
        save_file({"occlusion": np.ascontiguousarray(occlusion, np.float32)}, str(tmp), metadata=meta)


def read_shadow_grid(path: Path) -> tuple[np.ndarray, np.ndarray, float]:
    """(occlusion [rows, cols] in [0, 1], origin (x, y), cell) as :func:`write_shadow_grid` wrote
    them; a ValueError saying what is wrong otherwise (a file that is no safetensors included)."""
    from safetensors import SafetensorError, safe_open

    try:
        with safe_open(str(path), "np") as f:
            meta = f.metadata() or {}
            if "occlusion" not in f.keys() or not {"origin", "cell"} <= set(meta):
                raise ValueError("expected an 'occlusion' grid with 'origin' and 'cell' metadata")
            occ = f.get_tensor("occlusion")
        origin, cell = np.asarray(json.loads(meta["origin"]), np.float64), float(meta["cell"])
    except (SafetensorError, json.JSONDecodeError, TypeError) as exc:
        raise ValueError(f"not a shadow layer file ({exc})") from None
    if occ.ndim != 2 or origin.shape != (2,) or not cell > 0 or not np.all(np.isfinite(occ)):
        raise ValueError("expected a 2-D finite occlusion grid, a 2-vector origin and a positive cell")
    return np.clip(occ, 0.0, 1.0).astype(np.float32), origin, cell
