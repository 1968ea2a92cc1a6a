"""Vehicle assets in the 3DRealCar layout, loaded as Gaussians in the vehicle frame.

A folder holds ``wlh.json`` and a splat PLY and/or a mesh. 3DRealCar fixed each car's forward
sign by hand, so some assets face -X: ``flip_forward`` turns the car half a turn about Z (a proper
rotation, so the frame stays right-handed), rotating positions, orientations and SH alike.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..gaussians import Gaussians
from ..io.mesh import read_mesh
from ..io.ply import read_splats
from ..traffic.assets import load_asset
from .config import MESH_SAMPLES
from .mesh_to_splats import mesh_to_splats

# Half turn about Z: (x, y, z) -> (-x, -y, z); quaternion (w, x, y, z) = (0, 0, 0, 1).
HALF_TURN_Z = np.array([0.0, 0.0, 0.0, 1.0])


@dataclass
class VehicleAsset:
    name: str
    gaussians: Gaussians  # in the 3DRealCar frame
    wlh: np.ndarray  # width, length, height in metres
    source: Path  # the PLY or mesh the Gaussians came from


def sh_half_turn_signs(k: int) -> np.ndarray:
    """Per-coefficient sign of real SH under (x, y, z) -> (-x, -y, z).

    In the 3DGS ordering the basis functions alternate between even and odd in (x, y) jointly
    (1, y, z, x, xy, yz, 3z^2-1, xz, x^2-y^2, ...), so the signs alternate +, -, +, -.
    """
    return np.where(np.arange(k) % 2 == 0, 1.0, -1.0).astype(np.float32)


def flip_forward(g: Gaussians) -> Gaussians:
    """The same car turned half a turn about its Z axis."""
    w, x, y, z = (g.quats[:, i].astype(np.float64) for i in range(4))
    quats = np.stack([-z, -y, x, w], 1)  # (0, 0, 0, 1) ⊗ q
    sh = g.sh * sh_half_turn_signs(g.sh.shape[1])[None, :, None]
    normals = None if g.normals is None else g.normals * np.array([-1, -1, 1], np.float32)
    return Gaussians(g.means * np.array([-1, -1, 1], np.float32), quats.astype(np.float32),
                     g.log_scales.copy(), g.opacity_logits.copy(), sh.astype(np.float32), normals, dict(g.extra))


def load_vehicle_asset(folder, *, flip: bool = False, from_mesh: bool = False, n_samples: int = MESH_SAMPLES,
                       seed: int = 0) -> VehicleAsset:
    """Gaussians of an asset folder: its splat PLY, or its mesh sampled when there is none
    (or when ``from_mesh``)."""
    folder = Path(folder)
    info = load_asset(folder, folder.name)
    if from_mesh and info.mesh is None:
        raise InputError(folder, "asset has no mesh to sample (from_mesh requested)")
    if info.splats is not None and not from_mesh:
        g, source = read_splats(info.splats, drop_invalid=True), info.splats
    else:
        g, source = mesh_to_splats(read_mesh(info.mesh), n_samples, seed=seed), info.mesh
    if len(g) == 0:
        raise InputError(source, "asset has no Gaussians")
    return VehicleAsset(folder.name, flip_forward(g) if flip else g, info.wlh, Path(source))


def actor_gaussians(manifest, actor, *, flip: bool = False, from_mesh: bool = False, n_samples: int = MESH_SAMPLES,
                    seed: int = 0) -> Gaussians:
    """An actor's Gaussians in its vehicle frame, from the files its manifest entry names."""
    if from_mesh or actor.splats is None:
        if actor.mesh is None:
            raise InputError(manifest.path or manifest.root, f"actor {actor.id!r} has no mesh to sample", "assets.mesh")
        g = mesh_to_splats(read_mesh(manifest.resolve(actor.mesh)), n_samples, seed=seed)
    else:
        g = read_splats(manifest.resolve(actor.splats), drop_invalid=True)
    return flip_forward(g) if flip else g
