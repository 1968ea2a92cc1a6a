"""Triangles of Blender objects as numpy arrays (world or local coordinates), with the albedo
of each triangle's material."""

from __future__ import annotations

import bpy
import numpy as np


def object_triangles(obj, world: bool = True):
    """(verts [V,3], tris [T,3], albedo [T,3] linear RGB) of one evaluated mesh object."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    ev = obj.evaluated_get(depsgraph)
    mesh = ev.to_mesh()
    try:
        mesh.calc_loop_triangles()
        verts = np.empty(len(mesh.vertices) * 3, np.float64)
        mesh.vertices.foreach_get("co", verts)
        verts = verts.reshape(-1, 3)
        tris = np.empty(len(mesh.loop_triangles) * 3, np.int64)
        mesh.loop_triangles.foreach_get("vertices", tris)
        mat_idx = np.empty(len(mesh.loop_triangles), np.int64)
        mesh.loop_triangles.foreach_get("material_index", mat_idx)
        table = np.array([list(m["albedo"]) if m is not None and "albedo" in m else [0.5, 0.5, 0.5]
                          for m in mesh.materials] or [[0.5, 0.5, 0.5]])
        albedo = table[np.clip(mat_idx, 0, len(table) - 1)]
    finally:
        ev.to_mesh_clear()
    if world:
        M = np.array(obj.matrix_world)
        verts = verts @ M[:3, :3].T + M[:3, 3]
    return verts, tris.reshape(-1, 3), albedo


def scene_triangles(objects):
    """All objects' triangles merged, in world coordinates."""
    vs, ts, cs, offset = [], [], [], 0
    for obj in objects:
        if obj.type != "MESH":
            continue
        v, t, c = object_triangles(obj)
        vs.append(v)
        ts.append(t + offset)
        cs.append(c)
        offset += len(v)
    return np.concatenate(vs), np.concatenate(ts), np.concatenate(cs)
