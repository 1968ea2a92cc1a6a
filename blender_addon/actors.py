"""Vehicles as actors: a root empty whose transform is the vehicle pose (3DRealCar frame).

The root empty's children are the vehicle's geometry (imported mesh objects and/or a splat
cloud) in the asset's own frame, turned by 180 degrees about Z when ``flip_forward`` is set. The
pose written to scene packages maps the asset's frame to the world, flip included, so the
backend can apply it to the asset PLY as is.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import bpy
import numpy as np
from mathutils import Matrix, Vector

from . import core
from .core import errors

FLIP = Matrix.Rotation(math.pi, 4, "Z")


def all_actors(scene: bpy.types.Scene) -> list[bpy.types.Object]:
    """Actor roots of ``scene``, ordered by instance id (stable export order)."""
    found = [ob for ob in scene.objects if ob.symdrive.role == "ACTOR"]
    return sorted(found, key=lambda ob: (ob.symdrive.instance_id, ob.symdrive.actor_id))


def actor_of(obj: bpy.types.Object | None) -> bpy.types.Object | None:
    """The actor root ``obj`` belongs to (itself or an ancestor), or None."""
    while obj is not None:
        if obj.symdrive.role == "ACTOR":
            return obj
        obj = obj.parent
    return None


def selected_actors(context, operator) -> set[bpy.types.Object]:
    """The actor roots of the selected objects; an error reported on ``operator`` when there are none."""
    roots = {actor_of(ob) for ob in context.selected_objects} - {None}
    if not roots:
        operator.report({"ERROR"}, "select at least one vehicle")
    return roots


def unique_actor_id(scene: bpy.types.Scene, wanted: str) -> str:
    # A plain name, as the manifest requires (no leading dot, no "..": ids become file names).
    base = re.sub(r"\.{2,}", ".", re.sub(r"[^A-Za-z0-9_.-]+", "_", wanted)).strip("_.")[:100] or "vehicle"
    taken = {ob.symdrive.actor_id for ob in scene.objects if ob.symdrive.role == "ACTOR"}
    if base not in taken:
        return base
    n = 2
    while f"{base}_{n}" in taken:
        n += 1
    return f"{base}_{n}"


def next_instance_id(scene: bpy.types.Scene) -> int:
    return 1 + max(
        (ob.symdrive.instance_id for ob in scene.objects if ob.symdrive.role == "ACTOR"), default=0
    )


def asset_frame(root: bpy.types.Object) -> Matrix:
    """Asset frame of an actor relative to its root: identity, or the forward flip."""
    return FLIP if root.symdrive.flip_forward else Matrix.Identity(4)


def asset_world_matrix(root: bpy.types.Object) -> Matrix:
    """World matrix of the asset frame (what the scene package calls the actor pose)."""
    return root.matrix_world @ asset_frame(root)


def apply_forward_flip(root: bpy.types.Object) -> None:
    """Re-seat the children when ``flip_forward`` changed (the flip is its own inverse)."""
    s = root.symdrive
    if s.role != "ACTOR" or s.flip_forward == s.flip_applied:
        return
    for child in root.children:
        child.matrix_basis = FLIP @ child.matrix_basis
    s.flip_applied = s.flip_forward


def geometry_points(root: bpy.types.Object) -> np.ndarray:
    """Vertex positions [N, 3] of every mesh below ``root``, in the root's frame."""
    to_root = np.array(root.matrix_world.inverted())
    chunks = []
    for ob in root.children_recursive:
        if ob.type != "MESH" or len(ob.data.vertices) == 0:
            continue
        co = np.empty(len(ob.data.vertices) * 3, dtype=np.float64)
        ob.data.vertices.foreach_get("co", co)
        M = to_root @ np.array(ob.matrix_world)
        chunks.append(co.reshape(-1, 3) @ M[:3, :3].T + M[:3, 3])
    return np.concatenate(chunks) if chunks else np.zeros((0, 3))


def read_wlh_file(path: Path) -> np.ndarray:
    """``wlh.json`` beside an asset, in metres, through the core's one reader (every form the
    project writes or documents); vehicle import and Fit to Size both come here."""
    return np.array(core.wlh.read_wlh(path), dtype=np.float64)


def measure_and_ground(root: bpy.types.Object, wlh: np.ndarray | None = None) -> None:
    """Record the actor's size and stand it on the ground below its current location.

    The ground offset is the depth of the geometry's underside below the origin (``h / 2`` for
    an asset centred as 3DRealCar centres them), so the underside lands exactly on the ground.
    """
    bpy.context.view_layer.update()
    pts = geometry_points(root)
    settings = root.symdrive
    if len(pts):
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        size = hi - lo
        measured = np.array([size[1], size[0], size[2]])
        settings.ground_offset = float(-lo[2])
    else:
        measured = None
    chosen = wlh if wlh is not None else measured
    if chosen is not None:
        settings.wlh = [float(v) for v in chosen]
        if measured is None:
            settings.ground_offset = 0.5 * float(chosen[2])
    root.location.z += settings.ground_offset


_GEOMETRY_TYPES = {"MESH", "CURVE", "SURFACE", "META", "FONT", "POINTCLOUD"}


def mask_geometry(root: bpy.types.Object) -> list[bpy.types.Object]:
    """Objects whose silhouette is the actor's mask: its meshes, or its splat clouds if it has no mesh."""
    parts = [ob for ob in root.children_recursive if ob.type in _GEOMETRY_TYPES]
    solid = [ob for ob in parts if ob.symdrive.role != "SPLATS"]
    return solid or parts


def splat_asset(root: bpy.types.Object) -> bpy.types.Object | None:
    """The splat cloud that is this actor's appearance in the backend (the first one found)."""
    return next((ob for ob in root.children_recursive if ob.symdrive.role == "SPLATS"), None)


# A car, van or small truck: anything outside this is almost surely in the wrong unit or on its side.
CAR_LENGTH_RANGE = (2.0, 8.0)


def size_problem(wlh) -> str | None:
    """Why a vehicle of size ``(w, l, h)`` is not car-sized, or None when it is."""
    w, l, h = (float(v) for v in wlh)
    lo, hi = CAR_LENGTH_RANGE
    if not lo <= l <= hi:
        return f"{l:.2f} m long (a vehicle is {lo:g} to {hi:g} m): wrong unit or scale?"
    if h > l:
        return f"{h:.2f} m high but {l:.2f} m long: wrong up axis?"
    return None


def asset_folder(root: bpy.types.Object) -> Path | None:
    """Folder of the actor's mesh file (or splat PLY): where its wlh.json would be."""
    s = root.symdrive
    if s.mesh_path:
        return Path(bpy.path.abspath(s.mesh_path)).parent
    splats = splat_asset(root)
    if splats is not None and splats.symdrive.ply_path:
        return Path(bpy.path.abspath(splats.symdrive.ply_path)).parent
    return None


def recentre(root: bpy.types.Object) -> None:
    """Move the actor's parts so that their box is centred on the actor origin (mesh-only actors)."""
    bpy.context.view_layer.update()
    pts = geometry_points(root)
    if not len(pts):
        return
    centre = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
    shift = Matrix.Translation(Vector(-centre))
    for child in root.children:
        child.matrix_basis = shift @ child.matrix_basis


def shift_height(root: bpy.types.Object, dz: float) -> None:
    """Raise the actor by ``dz``: its location, and every key of an animated location Z."""
    from . import compat

    keyed = [
        fc for fc in compat.object_fcurves(root) if fc.data_path == "location" and fc.array_index == 2
    ]
    for fc in keyed:
        for k in fc.keyframe_points:
            k.co.y += dz
            k.handle_left.y += dz
            k.handle_right.y += dz
        fc.update()
    root.location.z += dz


def fit_size(root: bpy.types.Object, target) -> np.ndarray:
    """Scale the actor's mesh data (never the empty) to ``target``.

    ``target`` is a length (uniform scale) or ``(w, l, h)`` (each axis of the actor frame
    scaled on its own). The geometry ends centred on the actor origin with its underside on the
    same ground as before. Returns the new ``(w, l, h)``. Actors with a splat cloud are refused:
    the backend renders the PLY as it is on disk.
    """
    if splat_asset(root) is not None:
        raise errors.InputError(
            root.symdrive.actor_id,
            "has a splat cloud: its size is that of the PLY on disk (scale the PLY, then re-import)",
            "splats",
        )
    bpy.context.view_layer.update()
    pts = geometry_points(root)
    if not len(pts):
        raise errors.InputError(root.symdrive.actor_id, "has no mesh geometry to fit", "mesh")
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    size = hi - lo  # actor frame: x = length, y = width, z = height
    if np.any(size <= 1e-9):
        raise errors.InputError(root.symdrive.actor_id, "geometry is flat: cannot fit a size", "mesh")
    target = np.atleast_1d(np.asarray(target, dtype=np.float64))
    if target.shape == (1,):
        if not target[0] > 0:
            raise errors.InputError(root.symdrive.actor_id, "length must be positive", "length")
        factors = np.full(3, target[0] / size[0])
    elif target.shape == (3,):
        if not np.all(target > 0):
            raise errors.InputError(root.symdrive.actor_id, "w, l, h must all be positive", "wlh")
        w, l, h = target
        factors = np.array([l, w, h]) / size
    else:
        raise ValueError(f"target must be a length or (w, l, h), got {target!r}")
    centre = 0.5 * (lo + hi)
    A = Matrix.Diagonal(Vector((*factors, 1.0)))
    A = Matrix.Translation(Vector(-factors * centre)) @ A  # scaled, then centred on the origin
    to_root = root.matrix_world.inverted()
    done = set()
    for ob in root.children_recursive:
        if ob.type != "MESH":
            continue
        if ob.data.users > 1:  # shared data would be scaled once per user
            ob.data = ob.data.copy()
        M = to_root @ ob.matrix_world  # object -> actor frame
        if ob.data.name in done:
            continue
        ob.data.transform(M.inverted() @ A @ M)
        ob.data.update()
        done.add(ob.data.name)
    old_offset = root.symdrive.ground_offset
    bpy.context.view_layer.update()
    pts = geometry_points(root)
    new_size = pts.max(axis=0) - pts.min(axis=0)
    s = root.symdrive
    s.ground_offset = float(-pts.min(axis=0)[2])
    s.wlh = [float(new_size[1]), float(new_size[0]), float(new_size[2])]
    shift_height(root, s.ground_offset - old_offset)
    return np.array(s.wlh)
