"""Coloured point clouds as PLY (x, y, z, nx, ny, nz float; red, green, blue uchar).

This is the layout COLMAP and most tools write for ``points3D.ply``; the scene package's
``background.points`` uses it to initialise the reconstruction.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..errors import InputError
from .atomic import atomic_path
from .ply import read_header, read_vertex_table

_DTYPE = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("nx", "<f4"), ("ny", "<f4"), ("nz", "<f4"),
                   ("red", "u1"), ("green", "u1"), ("blue", "u1")])
_PLY_NAMES = {"f4": "float", "u1": "uchar", "f8": "double", "i4": "int", "u2": "ushort"}


def write_points(path: str | os.PathLike, points, colors, normals=None) -> Path:
    """Write points [N,3] with colours [N,3] in [0, 1] (and optional normals) atomically."""
    points = np.asarray(points)
    n = len(points)
    table = np.zeros(n, dtype=_DTYPE)
    for i, c in enumerate("xyz"):
        table[c] = points[:, i]
        if normals is not None:
            table["n" + c] = np.asarray(normals)[:, i]
    rgb = np.rint(np.clip(np.asarray(colors, dtype=np.float64), 0, 1) * 255).astype(np.uint8)
    for i, c in enumerate(("red", "green", "blue")):
        table[c] = rgb[:, i]
    header = ["ply", "format binary_little_endian 1.0", f"element vertex {n}"]
    header += [f"property {_PLY_NAMES[_DTYPE[name].str[1:]]} {name}" for name in _DTYPE.names]
    header.append("end_header")
    path = Path(path)
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        f.write(("\n".join(header) + "\n").encode("ascii"))
        table.tofile(f)
    return path


def read_points(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """(points [N,3] float32, colours [N,3] float32 in [0, 1]) from a point PLY, binary or ASCII,
    read by the same vertex reader as splat files (sizes checked against the header)."""
    path = Path(path)
    table = read_vertex_table(path, read_header(path))
    missing = [c for c in ("x", "y", "z", "red", "green", "blue") if c not in table.dtype.names]
    if missing:
        raise InputError(path, f"point cloud lacks {', '.join(missing)}", "element vertex")
    pts = np.stack([table[c] for c in "xyz"], 1).astype(np.float32)
    scale = 255.0 if np.issubdtype(table.dtype["red"], np.integer) else 1.0
    rgb = np.stack([table[c] for c in ("red", "green", "blue")], 1).astype(np.float32) / scale
    return pts, rgb
