"""Vehicle meshes through Blender's own importers (OBJ, PLY, glTF), returning what they created."""

from __future__ import annotations

from pathlib import Path

import addon_utils
import bpy
import numpy as np
from mathutils import Matrix

from .core import errors, ply

MESH_SUFFIXES = {".obj", ".ply", ".glb", ".gltf"}


def is_splat_ply(path: Path) -> bool:
    """True when ``path`` is a PLY whose vertices carry 3DGS fields, plain or compressed
    (checked from the header)."""
    if path.suffix.lower() != ".ply":
        return False
    header = ply.read_header(path)
    vertex = header.element("vertex")
    names = {n for n, _ in vertex.properties} if vertex is not None else set()
    return {"f_dc_0", "opacity", "rot_0"} <= names or ply.compressed_ply.is_compressed(
        [e.name for e in header.elements], names)


AXES = {
    "X": (1, 0, 0), "Y": (0, 1, 0), "Z": (0, 0, 1),
    "NEGATIVE_X": (-1, 0, 0), "NEGATIVE_Y": (0, -1, 0), "NEGATIVE_Z": (0, 0, -1),
}
GLTF_SUFFIXES = {".glb", ".gltf"}
# Blender's glTF importer always turns glTF's +Y up into Blender's +Z: file (x, y, z) -> (x, -z, y).
_GLTF_TO_BLENDER = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


def default_axes(path: Path) -> tuple[str, str]:
    """(up, forward) of a file when the user does not say: glTF is +Y up and faces +Z (the glTF
    convention for a model's front), everything else is taken to be in the 3DRealCar frame."""
    return ("Y", "Z") if path.suffix.lower() in GLTF_SUFFIXES else ("Z", "X")


def axis_matrix(up: str, forward: str) -> np.ndarray:
    """3x3 rotation taking file coordinates to the actor frame (X forward, Z up, Y to the left)."""
    if up not in AXES or forward not in AXES:
        raise ValueError(f"unknown axis {up if up not in AXES else forward!r} (expected one of {sorted(AXES)})")
    u, f = np.array(AXES[up], float), np.array(AXES[forward], float)
    if abs(u @ f) > 0.5:
        raise ValueError(f"up axis {up} and forward axis {forward} must be perpendicular")
    return np.stack([f, np.cross(u, f), u])


def import_mesh(path: Path, up_axis: str = "AUTO", forward_axis: str = "AUTO") -> list[bpy.types.Object]:
    """Import a mesh file and return the new objects, turned into the actor frame (X forward, Z up).

    ``up_axis`` and ``forward_axis`` name the file's axes that point up and to the vehicle's
    front (``"AUTO"``: :func:`default_axes`). Raises ``InputError`` when the importer fails or
    produces no geometry, or the axes are not perpendicular.
    """
    suffix = path.suffix.lower()
    if suffix not in MESH_SUFFIXES:
        raise errors.InputError(
            path, f"unsupported mesh format {suffix!r} (expected .obj, .ply, .glb or .gltf)"
        )
    if not path.is_file():
        raise errors.InputError(path, "file not found")
    up_default, forward_default = default_axes(path)
    up = up_default if up_axis == "AUTO" else up_axis
    forward = forward_default if forward_axis == "AUTO" else forward_axis
    try:
        to_actor = axis_matrix(up, forward)
    except ValueError as exc:
        raise errors.InputError(path, str(exc), "axes") from None
    before = set(bpy.data.objects)
    try:
        if suffix == ".obj":  # raw file coordinates (Blender's +Y forward, +Z up is the identity)
            result = bpy.ops.wm.obj_import(filepath=str(path), forward_axis="Y", up_axis="Z")
        elif suffix == ".ply":
            result = bpy.ops.wm.ply_import(filepath=str(path), forward_axis="Y", up_axis="Z")
        else:
            addon_utils.enable("io_scene_gltf2", default_set=False)
            result = bpy.ops.import_scene.gltf(filepath=str(path))
            to_actor = to_actor @ _GLTF_TO_BLENDER.T  # undo the importer's turn, then ours
    except RuntimeError as exc:
        _remove(set(bpy.data.objects) - before)
        raise errors.InputError(path, f"Blender's importer failed: {str(exc).strip()}") from None
    created = [ob for ob in bpy.data.objects if ob not in before]
    if "FINISHED" not in result or not any(ob.type == "MESH" for ob in created):
        _remove(created)
        raise errors.InputError(path, "the importer produced no mesh")
    if not any(len(ob.data.polygons) for ob in created if ob.type == "MESH"):
        _remove(created)  # e.g. an OBJ whose face lines the importer refused (Blender's log says why)
        raise errors.InputError(path, "the importer produced no faces", "f")
    if not np.allclose(to_actor, np.eye(3)):
        turn = Matrix(to_actor.tolist()).to_4x4()
        for ob in created:
            if ob.parent not in created:
                ob.matrix_basis = turn @ ob.matrix_basis
    return created


def _remove(objects) -> None:
    for ob in list(objects):
        bpy.data.objects.remove(ob, do_unlink=True)
