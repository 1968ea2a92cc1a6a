"""Vehicles as actors: a root empty whose transform is the vehicle pose (3DRealCar frame).

The root empty's children are the vehicle's geometry (imported mesh objects and/or a splat
cloud) in the asset's own frame, turned by 180 degrees about Z when ``flip_forward`` is set. The
pose written to scene packages maps the asset's frame to the world, flip included, so the
backend can apply it to the asset PLY as is.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import bpy
import numpy as np
from mathutils import Matrix

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


def unique_actor_id(scene: bpy.types.Scene, wanted: str) -> str:
    base = re.sub(r"[^A-Za-z0-9_.-]+", "_", wanted).strip("_") or "vehicle"
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
    """``wlh.json`` beside an asset: ``[w, l, h]`` or ``{"w": .., "l": .., "h": ..}`` in metres."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise errors.InputError(path, f"cannot read: {exc}") from None
    if isinstance(data, dict):
        data = [data.get(k, data.get(long)) for k, long in (("w", "width"), ("l", "length"), ("h", "height"))]
    try:
        wlh = np.array([float(v) for v in data], dtype=np.float64)
    except (TypeError, ValueError):
        raise errors.InputError(path, "expected [w, l, h] or {'w', 'l', 'h'} in metres", "wlh") from None
    if wlh.shape != (3,) or not np.all(np.isfinite(wlh)) or np.any(wlh <= 0):
        raise errors.InputError(path, "expected three positive sizes in metres", "wlh")
    return wlh


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
