"""Compressed splat PLY files (SuperSplat ``.compressed.ply``) for tests, written with plyfile."""

import numpy as np
from plyfile import PlyData, PlyElement

CHUNK_FIELDS = ["min_x", "min_y", "min_z", "max_x", "max_y", "max_z",
                "min_scale_x", "min_scale_y", "min_scale_z", "max_scale_x", "max_scale_y", "max_scale_z"]
COLOUR_FIELDS = ["min_r", "min_g", "min_b", "max_r", "max_g", "max_b"]


def write_compressed_ply(path, chunks, packed, sh=None, colour_bounds=True):
    """``chunks``: rows of bounds; ``packed``: (position, rotation, scale, colour) words per splat."""
    fields = CHUNK_FIELDS + (COLOUR_FIELDS if colour_bounds else [])
    chunk = np.empty(len(chunks), dtype=[(f, "<f4") for f in fields])
    for i, f in enumerate(fields):
        chunk[f] = [c[i] for c in chunks]
    vertex = np.empty(len(packed), dtype=[(f, "<u4") for f in
                                          ("packed_position", "packed_rotation", "packed_scale", "packed_color")])
    for i, f in enumerate(vertex.dtype.names):
        vertex[f] = [p[i] for p in packed]
    elements = [PlyElement.describe(chunk, "chunk"), PlyElement.describe(vertex, "vertex")]
    if sh is not None:
        table = np.empty(len(packed), dtype=[(f"f_rest_{i}", "u1") for i in range(sh.shape[1])])
        for i in range(sh.shape[1]):
            table[f"f_rest_{i}"] = sh[:, i]
        elements.append(PlyElement.describe(table, "sh"))
    PlyData(elements, byte_order="<").write(str(path))


def pack_11_10_11(x, y, z):
    return (x << 21) | (y << 11) | z


# One chunk: positions in [0,2]x[0,4]x[0,8], log-scales in [-5,-1], colours in [0,1].
BOX = [0, 0, 0, 2, 4, 8, -5, -5, -5, -1, -1, -1, 0, 0, 0, 1, 1, 1]
