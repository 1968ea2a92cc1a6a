"""Mesh files in: OBJ with the project's own parser, glTF/GLB, PLY, STL, OFF with trimesh.

:func:`read_mesh` reads any mesh file: OBJ with the project's own parser (:func:`read_obj`, so
the shipped assets sample exactly as before), and glTF/GLB, PLY, STL, OFF (and an OBJ that
parser cannot read) with trimesh, scenes flattened with their node transforms. glTF is +Y up:
it is turned to the vehicle frame's +Z up exactly as Blender's glTF importer does,
``(x, y, z) -> (x, -z, y)``; other formats are taken as Z up. Materials are kept as read (the
colour rules are the sampler's, :mod:`symdrive_core.insertion.mesh_to_splats`).
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..conventions import srgb_to_linear
from ..errors import InputError

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
