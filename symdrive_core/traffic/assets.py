"""The pool of vehicle assets traffic draws from: 3DRealCar-layout folders with ``wlh.json``.

A folder holds ``wlh.json`` (read by :mod:`symdrive_core.io.wlh`:
``{"wlh": [w, l, h], "splats": "splats.ply", "mesh": "mesh.obj"}``, the file names optional) and
the splat PLY and/or mesh it names. Each SUMO vehicle type is one asset, so the simulated vehicle
has exactly the asset's length and width.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io.wlh import read_wlh_info

# File names looked for when ``wlh.json`` names none (the first that exists is taken).
DEFAULT_FILES = {"splats": ("splats.ply",), "mesh": ("mesh.obj", "mesh.glb", "mesh.gltf", "mesh.ply")}


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
    wlh, info = read_wlh_info(folder / "wlh.json")
    files = {}
    for key, defaults in DEFAULT_FILES.items():
        names = [info[key]] if key in info else defaults
        files[key] = next((folder / n for n in names if isinstance(n, str) and (folder / n).exists()), None)
    if files["splats"] is None and files["mesh"] is None:
        raise InputError(folder, "asset folder has neither a splat PLY nor a mesh")
    return Asset(name, folder.resolve(), np.asarray(wlh, dtype=np.float64), files["splats"], files["mesh"])


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
