"""Mesh -> Gaussians by area-weighted surface sampling.

A 3DRealCar asset may ship only a mesh, and a car imported into Blender may be any mesh. Each
surface sample becomes a flat Gaussian lying in the face (thin along its normal) whose radius
follows the sample spacing, coloured from the surface's base colour.

:func:`read_mesh` reads any mesh file: OBJ with the project's own parser (:func:`read_obj`, so
the shipped assets sample exactly as before), and glTF/GLB, PLY, STL, OFF (and an OBJ that
parser cannot read) with trimesh, scenes flattened with their node transforms. glTF is +Y up:
it is turned to the vehicle frame's +Z up exactly as Blender's glTF importer does,
``(x, y, z) -> (x, -z, y)``; other formats are taken as Z up.

Colour, for an OBJ read by :func:`read_obj`: the texture (``map_Kd`` at the interpolated UV),
else the vertex colours, else the material ``Kd``. OBJ ``Kd`` is linear albedo, shown through
the sRGB curve as a studio-lit capture would be; textures and vertex colours are taken as
already display-encoded. For a mesh read with trimesh, the glTF rule: base colour factor x
texture at UV x vertex colour, multiplied in linear light (glTF factors and vertex colours are
linear, textures sRGB; PLY vertex colours are taken as display-encoded, OBJ ``Kd`` as linear).
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..conventions import linear_to_srgb, srgb_to_linear
from ..errors import InputError
from ..gaussians import Gaussians
from ..insertion.surface import sample_surface, surface_splats, surfel_spacing, triangle_areas

DEFAULT_COLOR = (0.5, 0.5, 0.5)


@dataclass
class TriMesh:
    verts: np.ndarray  # [V, 3]
    tris: np.ndarray  # [T, 3] vertex indices
    vert_colors: np.ndarray | None = None  # [V, 3] in [0, 1]
    uvs: np.ndarray | None = None  # [U, 2]
    tri_uvs: np.ndarray | None = None  # [T, 3] uv indices (-1 where the face has none)
    tri_material: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))  # [T], -1 = none
    # {"name", "kd" (linear), "texture" [H,W,3] | None}; trimesh-read meshes add "multiply": True,
    # "vertex_colored" and "vertex_linear" (the glTF rule, see the module docstring)
    materials: list[dict] = field(default_factory=list)


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
                if len(parts) < 4:
                    raise ValueError("a vertex needs x, y and z")
                verts.append([float(v) for v in parts[1:4]])
                colors.append([float(v) for v in parts[4:7]] if len(parts) >= 7 else None)
            elif parts[0] == "vt":
                uvs.append([float(v) for v in parts[1:3]])
            elif parts[0] == "mtllib":
                mtl = path.parent / " ".join(parts[1:])
                # Beside the OBJ only (a name in a downloaded file is data, not a path to follow),
                # and a regular file; a missing library leaves the default colour, as in Blender.
                if mtl.is_file() and mtl.resolve().is_relative_to(path.parent.resolve()):
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


# glTF +Y up -> vehicle frame +Z up, as Blender's glTF importer turns it: (x, y, z) -> (x, -z, y).
Y_UP_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
# Formats trimesh reads with numpy (and Pillow, for textures) alone.
TRIMESH_TYPES = {".glb": "glb", ".gltf": "gltf", ".ply": "ply", ".stl": "stl", ".off": "off", ".obj": "obj"}
NOT_READ = {".fbx": "FBX", ".usd": "USD", ".usda": "USD", ".usdc": "USD", ".usdz": "USD", ".blend": "Blender",
            ".dae": "COLLADA", ".3ds": "3DS", ".abc": "Alembic", ".x3d": "X3D"}


def _sniff_type(path: Path) -> str | None:
    """File type from the first bytes where they say (a GLB or PLY under another name), else the suffix."""
    try:
        with open(path, "rb") as f:
            head = f.read(4)
    except OSError as exc:
        raise InputError(path, f"cannot read: {exc.strerror or exc}") from None
    if head == b"glTF":
        return "glb"
    if head[:3] == b"ply":
        return "ply"
    return TRIMESH_TYPES.get(path.suffix.lower())


def _texture_array(image) -> np.ndarray | None:
    """A PIL image (what trimesh loads textures as) -> float32 [H, W, 3] in [0, 1]."""
    if image is None:
        return None
    try:
        return np.asarray(image.convert("RGB"), dtype=np.float32) / 255.0
    except Exception:  # noqa: BLE001 - a texture that does not decode leaves the base colour factor
        return None


def _part_colour(g, y_up: bool):
    """(material dict, per-vertex uv or None, per-vertex colour or None) of one trimesh geometry."""
    visual = getattr(g, "visual", None)
    kind = getattr(visual, "kind", None)
    material = {"name": "", "kd": srgb_to_linear(DEFAULT_COLOR), "texture": None, "multiply": True,
                "vertex_colored": False, "vertex_linear": y_up}
    uv = colors = None
    if kind == "texture":
        mat = visual.material
        factor, tex = None, None
        if hasattr(mat, "baseColorFactor") or hasattr(mat, "baseColorTexture"):  # PBR (glTF)
            factor = getattr(mat, "baseColorFactor", None)
            tex = _texture_array(getattr(mat, "baseColorTexture", None))
            material["kd"] = np.ones(3) if factor is None else np.asarray(factor, np.float64)[:3] / 255.0
        else:  # simple material (OBJ/MTL): Kd is linear albedo; a texture replaces it, as in read_obj
            tex = _texture_array(getattr(mat, "image", None))
            diffuse = getattr(mat, "diffuse", None)
            material["kd"] = (np.ones(3) if tex is not None or diffuse is None
                              else np.asarray(diffuse, np.float64)[:3] / 255.0)
        material["name"] = str(getattr(mat, "name", "") or "")
        material["texture"] = tex
        if tex is not None and visual.uv is not None and len(visual.uv) == len(g.vertices):
            uv = np.asarray(visual.uv, dtype=np.float64)
        vc = getattr(visual, "vertex_attributes", {}).get("color")
        if vc is not None and len(vc) == len(g.vertices):
            colors = np.asarray(vc, dtype=np.float64)[:, :3] / 255.0
    elif kind == "vertex":
        colors = np.asarray(visual.vertex_colors, dtype=np.float64)[:, :3] / 255.0
        material["kd"] = np.ones(3)
    if colors is not None:
        material["vertex_colored"] = True
    return material, uv, colors


def read_trimesh(path: str | os.PathLike, file_type: str | None = None) -> TriMesh:
    """Any mesh trimesh reads (glTF/GLB, PLY, STL, OFF, OBJ), scenes flattened with their node
    transforms, glTF turned from +Y up to +Z up."""
    path = Path(path)
    file_type = file_type or _sniff_type(path)
    if file_type is None:
        fmt = NOT_READ.get(path.suffix.lower())
        hint = f"{fmt} is not read here; " if fmt else ""
        raise InputError(path, f"unsupported mesh format {path.suffix or '(no suffix)'!r}: {hint}export the "
                         "mesh as GLB (or OBJ, PLY)")
    try:
        import trimesh
    except ImportError:
        raise InputError(path, "reading this mesh needs trimesh (pip install trimesh)") from None
    try:
        with warnings.catch_warnings():  # trimesh's own deprecation notices are not the user's concern
            warnings.simplefilter("ignore")
            scene = trimesh.load(str(path), file_type=file_type, force="scene", process=False)
        nodes = [(scene.graph[node][0], scene.geometry[scene.graph[node][1]]) for node in scene.graph.nodes_geometry]
    except InputError:
        raise
    except Exception as exc:  # noqa: BLE001 - trimesh raises many kinds; all mean "cannot read this file"
        raise InputError(path, f"cannot read {file_type.upper()} mesh: {type(exc).__name__}: {exc}") from None
    y_up = file_type in ("glb", "gltf")
    verts, tris, uvs, tri_uvs, colors, tri_mat, materials = [], [], [], [], [], [], []
    offset = 0
    for transform, g in nodes:
        faces = np.asarray(getattr(g, "faces", np.zeros((0, 3))), dtype=np.int64).reshape(-1, 3)
        if len(faces) == 0:
            continue  # points, lines, empty nodes: no surface to sample
        v = np.asarray(g.vertices, dtype=np.float64)
        fc = None
        if getattr(g.visual, "kind", None) == "face":  # face colours: one vertex per face corner
            fc = np.repeat(np.asarray(g.visual.face_colors, dtype=np.float64)[:, :3] / 255.0, 3, axis=0)
            v, faces = v[faces.ravel()], np.arange(3 * len(faces)).reshape(-1, 3)
        T = np.asarray(transform, dtype=np.float64)
        v = v @ T[:3, :3].T + T[:3, 3]
        if y_up:
            v = v @ Y_UP_TO_Z_UP.T
        if fc is not None:
            material, uv, vc = ({"name": "", "kd": np.ones(3), "texture": None, "multiply": True,
                                 "vertex_colored": True, "vertex_linear": False}, None, fc)
        else:
            material, uv, vc = _part_colour(g, y_up)
        verts.append(v)
        tris.append(faces + offset)
        uvs.append(uv if uv is not None else np.zeros((len(v), 2)))
        tri_uvs.append(faces + offset if uv is not None else np.full_like(faces, -1))
        colors.append(vc)
        tri_mat.append(np.full(len(faces), len(materials), dtype=np.int64))
        materials.append(material)
        offset += len(v)
    if not verts:
        raise InputError(path, "mesh has no faces (points or lines only, or an empty scene)")
    V = np.concatenate(verts)
    if not np.isfinite(V).all():
        raise InputError(path, "mesh has non-finite vertex coordinates")
    any_colors = any(c is not None for c in colors)
    vert_colors = (np.concatenate([c if c is not None else np.ones((len(v), 3)) for c, v in zip(colors, verts)])
                   if any_colors else None)
    any_uv = any(m["texture"] is not None for m in materials)
    return TriMesh(V, np.concatenate(tris), vert_colors,
                   np.concatenate(uvs) if any_uv else None,
                   np.concatenate(tri_uvs) if any_uv else None, np.concatenate(tri_mat), materials)


def read_mesh(path: str | os.PathLike) -> TriMesh:
    """A mesh file of any format read here (see the module docstring), in the vehicle frame."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "mesh file not found")
    file_type = _sniff_type(path)
    if file_type == "obj":
        try:
            return read_obj(path)
        except InputError as exc:
            obj_error = exc
        try:
            return read_trimesh(path, "obj")
        except InputError:
            raise obj_error from None
    return read_trimesh(path, file_type)


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


def mesh_to_splats(mesh: TriMesh, n: int = 12000, *, seed: int = 0, flatness: float = 0.1,
                   spacing_factor: float = 1.2, opacity: float = 0.95) -> Gaussians:
    """``n`` flat Gaussians covering the mesh surface, degree-0 SH from the surface colour."""
    if n <= 0:
        raise ValueError(f"mesh_to_splats: n must be positive, got {n}")
    points, normals, tri = sample_surface(mesh.verts, mesh.tris, n, np.random.default_rng(seed))
    spacing = surfel_spacing(float(triangle_areas(mesh.verts, mesh.tris).sum()), n)
    return surface_splats(points, normals, sample_colors(mesh, points, tri), spacing_factor * spacing,
                          flatness=flatness, opacity=opacity)
