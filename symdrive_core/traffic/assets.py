"""The pool of vehicle assets traffic draws from: 3DRealCar-layout folders with ``wlh.json``.

A folder holds ``wlh.json`` (``{"wlh": [w, l, h], "splats": "splats.ply", "mesh": "mesh.obj"}``,
the file names optional) and the splat PLY and/or mesh it names. Each SUMO vehicle type is one
asset, so the simulated vehicle has exactly the asset's length and width.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError

DEFAULT_FILES = {"splats": "splats.ply", "mesh": "mesh.obj"}


@dataclass(frozen=True)
class Asset:
    name: str  # SUMO vehicle type id
    folder: Path
    wlh: np.ndarray  # width, length, height in metres
    splats: Path | None
    mesh: Path | None

    @property
    def length(self) -> float:
        return float(self.wlh[1])


def load_asset(folder: Path, name: str) -> Asset:
    path = folder / "wlh.json"
    try:
        info = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise InputError(path, f"cannot read: {exc.strerror}") from None
    except json.JSONDecodeError as exc:
        raise InputError(path, f"not valid JSON: {exc.msg}") from None
    wlh = np.asarray(info.get("wlh") if isinstance(info, dict) else None, dtype=object)
    if wlh.shape != (3,) or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and v > 0
                                    for v in wlh):
        raise InputError(path, "expected three positive sizes in metres", "wlh")
    files = {}
    for key, default in DEFAULT_FILES.items():
        rel = info.get(key, default)
        files[key] = folder / rel if isinstance(rel, str) and (folder / rel).exists() else None
    if files["splats"] is None and files["mesh"] is None:
        raise InputError(folder, "asset folder has neither a splat PLY nor a mesh")
    return Asset(name, folder.resolve(), wlh.astype(np.float64), files["splats"], files["mesh"])


def asset_pool(folders: list[Path]) -> list[Asset]:
    """Assets from folders that hold ``wlh.json`` directly or anywhere below them."""
    found: list[Path] = []
    for folder in folders:
        folder = Path(folder)
        if not folder.is_dir():
            raise InputError(folder, "not a directory")
        found += sorted(p.parent for p in folder.rglob("wlh.json"))
    unique = list(dict.fromkeys(p.resolve() for p in found))
    return [load_asset(folder, f"asset{k}") for k, folder in enumerate(unique)]
