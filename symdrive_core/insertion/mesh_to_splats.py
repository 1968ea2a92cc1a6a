"""Mesh -> Gaussians by area-weighted surface sampling (numpy only).

A 3DRealCar asset may ship only a mesh. Each surface sample becomes a flat Gaussian lying in
the face (thin along its normal) whose radius follows the sample spacing, coloured from the
texture (``map_Kd`` at the interpolated UV), else the vertex colours, else the material ``Kd``.
OBJ ``Kd`` is linear albedo, shown through the sRGB curve as a studio-lit capture would be;
textures and vertex colours are taken as already display-encoded.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..gaussians import Gaussians
from ..world.sampling import sample_surface, surface_splats, surfel_spacing, triangle_areas

DEFAULT_COLOR = (0.5, 0.5, 0.5)


@dataclass
class TriMesh:
    verts: np.ndarray  # [V, 3]
    tris: np.ndarray  # [T, 3] vertex indices
    vert_colors: np.ndarray | None = None  # [V, 3] in [0, 1]
    uvs: np.ndarray | None = None  # [U, 2]
    tri_uvs: np.ndarray | None = None  # [T, 3] uv indices (-1 where the face has none)
    tri_material: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))  # [T], -1 = none
    materials: list[dict] = field(default_factory=list)  # {"name", "kd" (linear), "texture" [H,W,3] | None}


def linear_to_srgb(x: np.ndarray) -> np.ndarray:
    x = np.clip(np.asarray(x, dtype=np.float64), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def _read_mtl(path: Path) -> dict[str, dict]:
    mats: dict[str, dict] = {}
    current = None
    for line in path.read_text(encoding="utf-8", errors="replace").splitlines():
        parts = line.split()
        if not parts or parts[0].startswith("#"):
            continue
        if parts[0] == "newmtl":
            current = {"name": " ".join(parts[1:]), "kd": np.array(DEFAULT_COLOR), "texture": None}
            mats[current["name"]] = current
        elif current is not None and parts[0] == "Kd" and len(parts) >= 4:
            current["kd"] = np.array([float(v) for v in parts[1:4]])
        elif current is not None and parts[0] == "map_Kd" and len(parts) >= 2:
            from ..io.images import read_image  # OpenImageIO only when a texture exists

            current["texture"] = read_image(path.parent / parts[-1], channels=3)
    return mats


def read_obj(path: str | os.PathLike) -> TriMesh:
    """Wavefront OBJ (polygons fan-triangulated, negative indices, ``v x y z r g b``, ``usemtl``)."""
    path = Path(path)
    if not path.exists():
        raise InputError(path, "mesh file not found")
    verts, colors, uvs, tris, tri_uvs, tri_mat = [], [], [], [], [], []
    mats: dict[str, dict] = {}
    names: list[str] = []
    current = -1
    for lineno, line in enumerate(path.read_text(encoding="utf-8", errors="replace").splitlines(), 1):
        parts = line.split()
        if not parts or parts[0].startswith("#"):
            continue
        try:
            if parts[0] == "v":
                verts.append([float(v) for v in parts[1:4]])
                colors.append([float(v) for v in parts[4:7]] if len(parts) >= 7 else None)
            elif parts[0] == "vt":
                uvs.append([float(v) for v in parts[1:3]])
            elif parts[0] == "mtllib":
                mtl = path.parent / " ".join(parts[1:])
                if mtl.exists():
                    mats.update(_read_mtl(mtl))
            elif parts[0] == "usemtl":
                name = " ".join(parts[1:])
                if name not in names:
                    names.append(name)
                current = names.index(name)
            elif parts[0] == "f":
                refs = [p.split("/") for p in parts[1:]]
                vi = [int(r[0]) for r in refs]
                ti = [int(r[1]) if len(r) > 1 and r[1] else 0 for r in refs]
                vi = [i - 1 if i > 0 else len(verts) + i for i in vi]
                ti = [i - 1 if i > 0 else (len(uvs) + i if i < 0 else -1) for i in ti]
                for k in range(1, len(vi) - 1):
                    tris.append([vi[0], vi[k], vi[k + 1]])
                    tri_uvs.append([ti[0], ti[k], ti[k + 1]])
                    tri_mat.append(current)
        except (ValueError, IndexError):
            raise InputError(path, f"line {lineno}: cannot parse {line.strip()!r}") from None
    if not verts or not tris:
        raise InputError(path, "mesh has no vertices or no faces")
    tris_a = np.asarray(tris, dtype=np.int64)
    if tris_a.min() < 0 or tris_a.max() >= len(verts):
        raise InputError(path, "a face refers to a vertex that does not exist")
    has_colors = all(c is not None for c in colors)
    materials = [mats.get(n, {"name": n, "kd": np.array(DEFAULT_COLOR), "texture": None}) for n in names]
    return TriMesh(np.asarray(verts, dtype=np.float64), tris_a,
                   np.clip(np.asarray(colors, dtype=np.float64), 0, 1) if has_colors else None,
                   np.asarray(uvs, dtype=np.float64) if uvs else None,
                   np.asarray(tri_uvs, dtype=np.int64), np.asarray(tri_mat, dtype=np.int64), materials)


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
        if tex is not None and mesh.uvs is not None and uv_idx is not None and (uv_idx >= 0).all():
            uv = np.einsum("nk,nkc->nc", bary[sel], mesh.uvs[uv_idx])
            out[sel] = _sample_texture(tex, uv)
        elif mesh.vert_colors is None:
            out[sel] = linear_to_srgb(info["kd"])
    return np.clip(out, 0.0, 1.0)


def mesh_to_splats(mesh: TriMesh, n: int = 12000, *, seed: int = 0, flatness: float = 0.1,
                   spacing_factor: float = 1.2, opacity: float = 0.95) -> Gaussians:
    """``n`` flat Gaussians covering the mesh surface, degree-0 SH from the surface colour."""
    if n <= 0:
        raise ValueError(f"mesh_to_splats: n must be positive, got {n}")
    points, normals, tri = sample_surface(mesh.verts, mesh.tris, n, np.random.default_rng(seed))
    spacing = surfel_spacing(float(triangle_areas(mesh.verts, mesh.tris).sum()), n)
    return surface_splats(points, normals, sample_colors(mesh, points, tri), spacing_factor * spacing,
                          flatness=flatness, opacity=opacity)
