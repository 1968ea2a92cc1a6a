"""Write sampled poses as keyframes (linear, so in-between frames do not overshoot)."""

from __future__ import annotations

import contextlib

import bpy
import numpy as np
from mathutils import Euler, Matrix, Quaternion

from . import compat, reference_frame


@contextlib.contextmanager
def _linear_keys():
    edit = bpy.context.preferences.edit
    old = edit.keyframe_new_interpolation_type
    edit.keyframe_new_interpolation_type = "LINEAR"
    try:
        yield
    finally:
        edit.keyframe_new_interpolation_type = old


def key_rotation_track(obj: bpy.types.Object, frame_numbers, locations, quats_wxyz) -> None:
    """Key location and a full rotation per frame, keeping Euler angles continuous."""
    obj.rotation_mode = "XYZ"
    previous = Euler((0.0, 0.0, 0.0))
    with _linear_keys():
        for f, loc, q in zip(
            frame_numbers, np.asarray(locations, float), np.asarray(quats_wxyz, float), strict=True
        ):
            euler = Quaternion(q).to_euler("XYZ", previous)
            obj.location = loc
            obj.rotation_euler = euler
            obj.keyframe_insert("location", frame=int(f))
            obj.keyframe_insert("rotation_euler", frame=int(f))
            previous = euler


def key_presence(obj: bpy.types.Object, frame_numbers, present) -> None:
    """Key "Disable in Renders" where presence changes, on the actor and its parts.

    An actor disabled in renders is absent from that frame of the export (its pose is null).
    """
    frame_numbers, present = list(frame_numbers), list(present)
    targets = [obj, *obj.children_recursive]
    for i, (f, here) in enumerate(zip(frame_numbers, present, strict=True)):
        if i > 0 and here == present[i - 1]:
            continue
        for ob in targets:
            ob.hide_render = not here
            ob.keyframe_insert("hide_render", frame=int(f))


def shift_keys(obj: bpy.types.Object, frames: float) -> None:
    """Move every key of ``obj`` and of its parts ``frames`` later (earlier when negative): a retime
    that keeps the track's shape, its presence keys included (they are keyed on the parts too)."""
    for ob in (obj, *obj.children_recursive):
        for fc in compat.object_fcurves(ob):
            for k in fc.keyframe_points:
                k.co.x += frames
                k.handle_left.x += frames
                k.handle_right.x += frames
            fc.update()


def disable_in_renders(obj: bpy.types.Object) -> None:
    """Disable ``obj`` and its parts in renders at every frame: keyed presence is set to hidden at
    each key too, or the next frame change would bring the vehicle back."""
    for ob in (obj, *obj.children_recursive):
        ob.hide_render = True
        for fc in compat.object_fcurves(ob):
            if fc.data_path == "hide_render":
                for k in fc.keyframe_points:
                    k.co.y = 1.0
                fc.update()


def key_world_poses(obj: bpy.types.Object, frame_numbers, world_matrices) -> None:
    """Key ``obj`` so that its world matrix is each of ``world_matrices`` (4x4) at the given frames."""
    locs, quats = [], []
    for M in world_matrices:
        loc, rot, _ = reference_frame.world_to_basis(obj, Matrix(np.asarray(M).tolist())).decompose()
        locs.append(tuple(loc))
        quats.append(tuple(rot))
    key_rotation_track(obj, frame_numbers, locs, quats)
