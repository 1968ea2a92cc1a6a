"""Splat PLY -> a vertex-only mesh object with named attributes, filled with ``foreach_set``.

Only what the viewport needs is copied into the .blend (position, opacity, scale, DC colour);
the full SH payload stays in the PLY, referenced by path and SHA-256 so the backend reads the
original and a changed file can be detected.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import bpy
import numpy as np

from . import splat_display
from .core import conventions, errors, ply


def file_sha256(path: str | Path) -> str:
    with open(path, "rb") as f:
        return hashlib.file_digest(f, "sha256").hexdigest()


def display_subset(count: int, max_points: int) -> np.ndarray | None:
    """Indices of a fixed random subset when a cloud is larger than ``max_points`` (0 = keep all)."""
    if max_points <= 0 or count <= max_points:
        return None
    return np.sort(np.random.default_rng(0).choice(count, size=max_points, replace=False))


def build_splat_mesh(name: str, gaussians, index: np.ndarray | None = None) -> bpy.types.Mesh:
    g = gaussians if index is None else gaussians.subset(index)
    n = len(g)
    mesh = bpy.data.meshes.new(name)
    mesh.vertices.add(n)
    mesh.vertices.foreach_set("co", np.ascontiguousarray(g.means, dtype=np.float32).ravel())
    opacity = g.opacities
    rgba = np.empty((n, 4), dtype=np.float32)
    rgba[:, :3] = conventions.srgb_to_linear(g.base_colors)  # 3DGS colours are sRGB; attributes linear
    rgba[:, 3] = opacity
    attrs = mesh.attributes
    attrs.new(splat_display.OPACITY_ATTRIBUTE, "FLOAT", "POINT").data.foreach_set("value", opacity)
    attrs.new(splat_display.SCALE_ATTRIBUTE, "FLOAT_VECTOR", "POINT").data.foreach_set(
        "vector", np.ascontiguousarray(g.scales, dtype=np.float32).ravel()
    )
    attrs.new(splat_display.COLOR_ATTRIBUTE, "FLOAT_COLOR", "POINT").data.foreach_set("color", rgba.ravel())
    mesh.update()
    return mesh


def import_splat_object(
    path: str | Path,
    collection: bpy.types.Collection,
    *,
    name: str | None = None,
    max_points: int = 0,
    point_size: float = 1.0,
) -> bpy.types.Object:
    """Read ``path`` (raises ``InputError`` for anything that is not a valid 3DGS PLY) and link the object."""
    path = Path(path).resolve()
    gaussians = ply.read_splats(path)
    if len(gaussians) == 0:
        raise errors.InputError(path, "no splats (0 vertices): nothing to show or render", "element vertex")
    index = display_subset(len(gaussians), max_points)
    name = name or path.stem
    obj = bpy.data.objects.new(name, build_splat_mesh(name, gaussians, index))
    settings = obj.symdrive
    settings.role = "SPLATS"
    settings.ply_path = str(path)
    settings.ply_sha256 = file_sha256(path)
    settings.splat_count = len(gaussians)
    settings.display_count = len(gaussians) if index is None else len(index)
    settings.sh_degree = gaussians.sh_degree
    splat_display.add_display_modifier(obj, point_size)
    collection.objects.link(obj)
    return obj
