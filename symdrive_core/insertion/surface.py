"""Area-uniform sampling of triangle meshes, and flat Gaussians ("surfels") on the samples.

Vehicle splat assets are made this way: each sample becomes a Gaussian lying in the surface
(thin along the normal), coloured with the material's albedo.
"""

from __future__ import annotations

import numpy as np

from ..gaussians import Gaussians
from ..rotations import quats_z_to


def triangle_areas(verts: np.ndarray, tris: np.ndarray) -> np.ndarray:
    a, b, c = (verts[tris[:, i]] for i in range(3))
    return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)


def sample_surface(verts, tris, n: int, rng: np.random.Generator, weights=None):
    """``n`` points uniformly by area (times optional per-triangle ``weights``).

    Returns (points [n,3], unit normals [n,3], triangle index [n]).
    """
    verts = np.asarray(verts, dtype=np.float64)
    tris = np.asarray(tris, dtype=np.int64)
    area = triangle_areas(verts, tris)
    p = area if weights is None else area * np.asarray(weights, dtype=np.float64)
    if not np.any(p > 0):
        raise ValueError("sample_surface: the mesh has no area to sample")
    idx = rng.choice(len(tris), size=n, p=p / p.sum())
    u, v = rng.random(n), rng.random(n)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    a, b, c = (verts[tris[idx, i]] for i in range(3))
    points = a + u[:, None] * (b - a) + v[:, None] * (c - a)
    normal = np.cross(b - a, c - a)
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
    return points, normal, idx


def surface_splats(points, normals, colors, spacing: float, flatness: float = 0.1,
                   opacity: float = 0.95) -> Gaussians:
    """Flat Gaussians on surface samples: radius ``spacing`` in the surface, ``flatness``
    times that along the normal; degree-0 SH from ``colors`` in [0, 1]."""
    n = len(points)
    scales = np.tile([spacing, spacing, spacing * flatness], (n, 1))
    return Gaussians.from_activated(points, quats_z_to(normals), scales, np.full(n, opacity),
                                    np.clip(colors, 0.0, 1.0))


def surfel_spacing(total_area: float, n: int) -> float:
    """Radius that makes ``n`` surfels cover ``total_area`` about once (a disc of r^2 * pi each)."""
    return float(np.sqrt(total_area / (np.pi * max(n, 1))))
