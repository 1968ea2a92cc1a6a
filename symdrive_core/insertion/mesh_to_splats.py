"""Mesh -> Gaussians by area-weighted surface sampling.

A 3DRealCar asset may ship only a mesh, and a car imported into Blender may be any mesh. Each
surface sample becomes a flat Gaussian lying in the face (thin along its normal) whose radius
follows the sample spacing, coloured from the surface's base colour. Mesh files are read by
:mod:`symdrive_core.io.mesh`.

Colour, for an OBJ read by :func:`~symdrive_core.io.mesh.read_obj`: the texture (``map_Kd`` at the interpolated UV),
else the vertex colours, else the material ``Kd``. OBJ ``Kd`` is linear albedo, shown through
the sRGB curve as a studio-lit capture would be; textures and vertex colours are taken as
already display-encoded. For a mesh read with trimesh, the glTF rule: base colour factor x
texture at UV x vertex colour, multiplied in linear light (glTF factors and vertex colours are
linear, textures sRGB; PLY vertex colours are taken as display-encoded, OBJ ``Kd`` as linear).
"""

from __future__ import annotations

import numpy as np

from ..conventions import linear_to_srgb, srgb_to_linear
from ..gaussians import Gaussians
from ..io.mesh import DEFAULT_COLOR, TriMesh
from .config import MESH_SAMPLES
from .surface import sample_surface, surface_splats, surfel_spacing, triangle_areas


def barycentric(points: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Barycentric weights [N, 3] of points lying in triangles (a, b, c)."""
    v0, v1, v2 = b - a, c - a, points - a
    d00, d01, d11 = (v0 * v0).sum(1), (v0 * v1).sum(1), (v1 * v1).sum(1)
    d20, d21 = (v2 * v0).sum(1), (v2 * v1).sum(1)
    den = np.where(np.abs(d00 * d11 - d01 * d01) > 1e-30, d00 * d11 - d01 * d01, 1.0)
    v = (d11 * d20 - d01 * d21) / den
    w = (d00 * d21 - d01 * d20) / den
    return np.stack([1.0 - v - w, v, w], 1)


def _sample_texture(tex: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear lookup with wrap-around; OBJ's v axis points up the image."""
    h, w = tex.shape[:2]
    x = (uv[:, 0] % 1.0) * w - 0.5
    y = (1.0 - uv[:, 1] % 1.0) * h - 0.5
    x0, y0 = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    x0, x1, y0, y1 = x0 % w, (x0 + 1) % w, y0 % h, (y0 + 1) % h
    return ((1 - fx) * (1 - fy) * tex[y0, x0] + fx * (1 - fy) * tex[y0, x1]
            + (1 - fx) * fy * tex[y1, x0] + fx * fy * tex[y1, x1])


def sample_colors(mesh: TriMesh, points: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Colour [N, 3] in [0, 1] at surface samples (texture > vertex colour > material Kd)."""
    a, b, c = (mesh.verts[mesh.tris[tri, i]] for i in range(3))
    bary = barycentric(points, a, b, c)
    out = np.tile(np.asarray(DEFAULT_COLOR, dtype=np.float64), (len(points), 1))
    if mesh.vert_colors is not None:
        out = np.einsum("nk,nkc->nc", bary, mesh.vert_colors[mesh.tris[tri]])
    mat = mesh.tri_material[tri] if len(mesh.tri_material) else np.full(len(tri), -1)
    for m, info in enumerate(mesh.materials):
        sel = mat == m
        if not sel.any():
            continue
        tex = info.get("texture")
        uv_idx = mesh.tri_uvs[tri[sel]] if mesh.tri_uvs is not None else None
        if info.get("multiply"):
            out[sel] = _multiplied_color(mesh, info, bary[sel], tri[sel], uv_idx)
            continue
        if tex is not None and mesh.uvs is not None and uv_idx is not None and (uv_idx >= 0).all():
            uv = np.einsum("nk,nkc->nc", bary[sel], mesh.uvs[uv_idx])
            out[sel] = _sample_texture(tex, uv)
        elif mesh.vert_colors is None:
            out[sel] = linear_to_srgb(info["kd"])
    return np.clip(out, 0.0, 1.0)


def _multiplied_color(mesh: TriMesh, info: dict, bary: np.ndarray, tri: np.ndarray,
                      uv_idx: np.ndarray | None) -> np.ndarray:
    """glTF base colour: factor x texture x vertex colour in linear light, display-encoded."""
    lin = np.tile(np.asarray(info["kd"], dtype=np.float64), (len(tri), 1))
    tex = info.get("texture")
    if tex is not None and mesh.uvs is not None and uv_idx is not None and (uv_idx >= 0).all():
        uv = np.einsum("nk,nkc->nc", bary, mesh.uvs[uv_idx])
        lin *= srgb_to_linear(_sample_texture(tex, uv))
    if info.get("vertex_colored") and mesh.vert_colors is not None:
        vc = np.clip(np.einsum("nk,nkc->nc", bary, mesh.vert_colors[mesh.tris[tri]]), 0.0, 1.0)
        lin *= vc if info.get("vertex_linear") else srgb_to_linear(vc)
    return linear_to_srgb(lin)


def mesh_to_splats(mesh: TriMesh, n: int = MESH_SAMPLES, *, seed: int = 0, flatness: float = 0.1,
                   spacing_factor: float = 1.2, opacity: float = 0.95) -> Gaussians:
    """``n`` flat Gaussians covering the mesh surface, degree-0 SH from the surface colour."""
    if n <= 0:
        raise ValueError(f"mesh_to_splats: n must be positive, got {n}")
    points, normals, tri = sample_surface(mesh.verts, mesh.tris, n, np.random.default_rng(seed))
    spacing = surfel_spacing(float(triangle_areas(mesh.verts, mesh.tris).sum()), n)
    return surface_splats(points, normals, sample_colors(mesh, points, tri), spacing_factor * spacing,
                          flatness=flatness, opacity=opacity)
