"""Vehicle meshes through Blender's own importers (OBJ, PLY, glTF), returning what they created."""

from __future__ import annotations

from pathlib import Path

import addon_utils
import bpy

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


def import_mesh(path: Path, up_axis: str = "Z") -> list[bpy.types.Object]:
    """Import a mesh file and return the new objects; ``up_axis`` is the file's up axis (OBJ/PLY).

    glTF is Y-up by definition and converted by its importer. Raises ``InputError`` when the
    importer fails or produces no geometry.
    """
    suffix = path.suffix.lower()
    if suffix not in MESH_SUFFIXES:
        raise errors.InputError(
            path, f"unsupported mesh format {suffix!r} (expected .obj, .ply, .glb or .gltf)"
        )
    if not path.is_file():
        raise errors.InputError(path, "file not found")
    forward = {"Z": "Y", "Y": "NEGATIVE_Z"}[up_axis]
    before = set(bpy.data.objects)
    try:
        if suffix == ".obj":
            result = bpy.ops.wm.obj_import(filepath=str(path), forward_axis=forward, up_axis=up_axis)
        elif suffix == ".ply":
            result = bpy.ops.wm.ply_import(filepath=str(path), forward_axis=forward, up_axis=up_axis)
        else:
            addon_utils.enable("io_scene_gltf2", default_set=False)
            result = bpy.ops.import_scene.gltf(filepath=str(path))
    except RuntimeError as exc:
        _remove(set(bpy.data.objects) - before)
        raise errors.InputError(path, f"Blender's importer failed: {str(exc).strip()}") from None
    created = [ob for ob in bpy.data.objects if ob not in before]
    if "FINISHED" not in result or not any(ob.type == "MESH" for ob in created):
        _remove(created)
        raise errors.InputError(path, "the importer produced no mesh")
    return created


def _remove(objects) -> None:
    for ob in list(objects):
        bpy.data.objects.remove(ob, do_unlink=True)
