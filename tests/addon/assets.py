"""Small vehicle and splat assets written inside the tests (nothing is downloaded)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from symdrive_core.gaussians import Gaussians
from symdrive_core.io.ply import write_splats

# A car-like shape in the 3DRealCar frame: a body and a cabin set towards the rear, so the shape
# is not symmetric front to back. Overall box: x in [-2, 2], y in [-0.9, 0.9], z in [-0.75, 0.75].
BOXES = [((-2.0, -0.9, -0.75), (2.0, 0.9, 0.25)), ((-1.5, -0.8, 0.25), (0.5, 0.8, 0.75))]
WLH = (1.8, 4.0, 1.5)


def box_mesh(lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """Vertices [8, 3] and triangles [12, 3] of an axis-aligned box."""
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    v = np.array([[x, y, z] for x in (x0, x1) for y in (y0, y1) for z in (z0, z1)], dtype=np.float64)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    tris = [t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))]
    return v, np.array(tris)


def car_mesh() -> tuple[np.ndarray, np.ndarray]:
    verts, tris = [], []
    for lo, hi in BOXES:
        v, t = box_mesh(lo, hi)
        tris.append(t + sum(len(x) for x in verts))
        verts.append(v)
    return np.concatenate(verts), np.concatenate(tris)


def write_obj(path: Path, verts: np.ndarray, tris: np.ndarray) -> Path:
    lines = [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in verts]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in tris]
    path.write_text("\n".join(lines) + "\n")
    return path


def surface_splats(verts: np.ndarray, tris: np.ndarray, n: int, seed: int = 0, degree: int = 0) -> Gaussians:
    """Small Gaussians sampled uniformly on a triangle mesh (a splat twin of the mesh)."""
    rng = np.random.default_rng(seed)
    a, b, c = (verts[tris[:, i]] for i in range(3))
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    pick = rng.choice(len(tris), size=n, p=area / area.sum())
    r1, r2 = rng.random(n), rng.random(n)
    s = np.sqrt(r1)
    pts = (1 - s)[:, None] * a[pick] + (s * (1 - r2))[:, None] * b[pick] + (s * r2)[:, None] * c[pick]
    k = (degree + 1) ** 2
    sh = np.zeros((n, k, 3), np.float32)
    sh[:, 0] = (rng.random((n, 3)) - 0.5) / 0.28209479177387814 * 0.8
    return Gaussians(
        means=pts.astype(np.float32),
        quats=np.tile(np.float32([1, 0, 0, 0]), (n, 1)),
        log_scales=np.full((n, 3), np.log(0.03), np.float32),
        opacity_logits=np.full(n, 3.0, np.float32),
        sh=sh,
    )


def write_car(folder: Path, name: str, seed: int = 0) -> tuple[Path, Path]:
    """(mesh OBJ, splat PLY) of the test car in ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    verts, tris = car_mesh()
    obj = write_obj(folder / f"{name}.obj", verts, tris)
    ply = folder / f"{name}.ply"
    write_splats(ply, surface_splats(verts, tris, 3000, seed))
    return obj, ply
