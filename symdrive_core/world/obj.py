"""Wavefront OBJ + MTL for vehicle meshes: polygons grouped by material, ``Kd`` = albedo.

Coordinates are written as they are (the 3DRealCar frame: X forward, Z up, metres); importers
must keep them (Blender: forward axis X, up axis Z).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..io.atomic import write_text_atomic


def write_obj(path: str | os.PathLike, verts, faces, face_materials, materials: list[tuple[str, tuple]]) -> Path:
    """``faces``: vertex-index tuples (any length); ``materials``: (name, linear RGB) per slot."""
    path = Path(path)
    mtl = path.with_suffix(".mtl")
    lines = [f"mtllib {mtl.name}", "# 3DRealCar frame: X forward, Y left, Z up, origin at the box centre"]
    lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in np.asarray(verts, dtype=np.float64)]
    order = np.argsort(np.asarray(face_materials), kind="stable")
    current = None
    for i in order:
        slot = face_materials[i]
        if slot != current:
            lines.append(f"usemtl {materials[slot][0]}")
            current = slot
        lines.append("f " + " ".join(str(int(v) + 1) for v in faces[i]))
    mtl_lines = []
    for name, rgb in materials:
        mtl_lines += [f"newmtl {name}", "Kd {:.6f} {:.6f} {:.6f}".format(*rgb), ""]
    write_text_atomic(mtl, "\n".join(mtl_lines))
    write_text_atomic(path, "\n".join(lines) + "\n")
    return path
