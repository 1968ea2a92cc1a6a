"""Mesh primitives built with ``from_pydata``: boxes, cylinders, extruded profiles, road strips.

Every primitive returns one mesh object linked to the scene, with per-face material indices,
so a whole car or a whole kerb is one object (cheap to render, simple to export).
"""

from __future__ import annotations

import bpy
import numpy as np
from mathutils import Matrix


def mesh_object(name, verts, faces, materials, face_materials=None, collection=None):
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata([tuple(map(float, v)) for v in verts], [], [tuple(map(int, f)) for f in faces])
    for m in materials:
        mesh.materials.append(m)
    if face_materials is not None:
        mesh.polygons.foreach_set("material_index", np.asarray(face_materials, dtype=np.int32))
    mesh.validate()
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    (collection or bpy.context.scene.collection).objects.link(obj)
    return obj


def place(obj, location, yaw=0.0):
    obj.matrix_world = Matrix.Translation(tuple(location)) @ Matrix.Rotation(yaw, 4, "Z")
    return obj


def box_geometry(x0, x1, y0, y1, z0, z1, offset=0):
    v = [(x, y, z) for z in (z0, z1) for y in (y0, y1) for x in (x0, x1)]
    f = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    return v, [tuple(i + offset for i in face) for face in f]


def box(name, size, location, yaw, material, collection=None):
    """Axis-aligned box (before ``yaw``) with its base centred on ``location``."""
    sx, sy, sz = size
    v, f = box_geometry(-sx / 2, sx / 2, -sy / 2, sy / 2, 0.0, sz)
    return place(mesh_object(name, v, f, [material], collection=collection), location, yaw)


def cylinder_geometry(radius, z0, z1, segments=12, offset=0, axis="z", center=(0.0, 0.0)):
    """Closed cylinder along ``axis`` ("z" or "y"), between z0 and z1 along that axis."""
    a = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    ring = np.stack([center[0] + radius * np.cos(a), center[1] + radius * np.sin(a)], 1)
    verts = []
    for h in (z0, z1):
        for p, q in ring:
            verts.append((p, q, h) if axis == "z" else (p, h, q))
    faces = [(i, (i + 1) % segments, segments + (i + 1) % segments, segments + i) for i in range(segments)]
    faces.append(tuple(reversed(range(segments))))
    faces.append(tuple(range(segments, 2 * segments)))
    if axis == "y":  # swapping two axes mirrors: flip windings back
        faces = [tuple(reversed(f)) for f in faces]
    return verts, [tuple(i + offset for i in f) for f in faces]


def cylinder(name, radius, height, location, material, segments=12, collection=None):
    v, f = cylinder_geometry(radius, 0.0, height, segments)
    return place(mesh_object(name, v, f, [material], collection=collection), location)


def extrude_profile(profile_xz, y0, y1, offset=0):
    """Extrude a closed counter-clockwise (x, z) polygon along y from y0 to y1.

    Returns vertices, faces, and for each face the index of the profile edge it comes from
    (-1 for the two caps), so callers can give edges their own material.
    """
    p = np.asarray(profile_xz, dtype=np.float64)
    n = len(p)
    verts = [(x, y0, z) for x, z in p] + [(x, y1, z) for x, z in p]
    faces, edge_of = [], []
    for i in range(n):
        j = (i + 1) % n
        faces.append((i + offset, j + offset, n + j + offset, n + i + offset))
        edge_of.append(i)
    faces.append(tuple(offset + i for i in range(n)))
    faces.append(tuple(offset + n + i for i in reversed(range(n))))
    edge_of += [-1, -1]
    return verts, faces, edge_of


def strip(name, path_xy, normals_xy, lateral, heights, material, collection=None):
    """A surface swept along a path: one cross-section polyline ``lateral[k], heights[k]``
    (offsets along the left normal, heights above the ground) at every path point."""
    path_xy, normals_xy = np.asarray(path_xy), np.asarray(normals_xy)
    lat, hz = np.asarray(lateral, dtype=np.float64), np.asarray(heights, dtype=np.float64)
    m, k = len(path_xy), len(lat)
    pts = path_xy[:, None, :] + lat[None, :, None] * normals_xy[:, None, :]
    verts = np.concatenate([pts, np.broadcast_to(hz[None, :, None], (m, k, 1))], axis=2).reshape(-1, 3)
    faces = []
    for i in range(m - 1):
        for j in range(k - 1):
            a, b = i * k + j, i * k + j + 1
            faces.append((a, a + k, b + k, b))
    return mesh_object(name, verts, faces, [material], collection=collection)
