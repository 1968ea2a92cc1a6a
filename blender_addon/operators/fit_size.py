"""Fit to Size: scale a vehicle's mesh data (never its empty) to a length, to w/l/h, or to its wlh.json."""

from __future__ import annotations

import bpy
from bpy.props import FloatProperty

from .. import actors
from ..core import errors


class SYMDRIVE_OT_fit_vehicle_size(bpy.types.Operator):
    """Scale the active vehicle's mesh to a length (uniformly), to w, l, h, or to the wlh.json beside
    its file. The empty keeps unit scale; the vehicle stays on the ground"""

    bl_idname = "symdrive.fit_vehicle_size"
    bl_label = "Fit to Size"
    bl_options = {"REGISTER", "UNDO"}

    length: FloatProperty(
        name="Length", default=0.0, min=0.0, unit="LENGTH", description="Scale uniformly to this length"
    )
    w: FloatProperty(name="Width", default=0.0, min=0.0, unit="LENGTH", description="With l and h: fit each axis")
    l: FloatProperty(name="Length (box)", default=0.0, min=0.0, unit="LENGTH")
    h: FloatProperty(name="Height", default=0.0, min=0.0, unit="LENGTH")

    @classmethod
    def poll(cls, context):
        return actors.actor_of(context.active_object) is not None

    def _target(self, root):
        if self.w > 0 and self.l > 0 and self.h > 0:
            return (self.w, self.l, self.h), "w, l, h"
        if self.length > 0:
            return self.length, "length"
        if self.w > 0 or self.l > 0 or self.h > 0:
            raise errors.InputError(root.symdrive.actor_id, "give all of w, l and h, or a length", "wlh")
        folder = actors.asset_folder(root)
        wlh_file = folder / "wlh.json" if folder is not None else None
        if wlh_file is None or not wlh_file.is_file():
            raise errors.InputError(
                root.symdrive.actor_id, "no wlh.json beside the asset: give a length or w, l, h", "wlh"
            )
        return actors.read_wlh_file(wlh_file), wlh_file.name

    def execute(self, context):
        root = actors.actor_of(context.active_object)
        if root is None:
            self.report({"ERROR"}, "select a vehicle (an actor imported with Import Vehicle)")
            return {"CANCELLED"}
        try:
            target, source = self._target(root)
            w, l, h = actors.fit_size(root, target)
        except errors.SymDriveError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        self.report(
            {"INFO"}, f"Actor {root.symdrive.actor_id!r} fitted ({source}): {l:.2f} m long, {w:.2f} m wide, {h:.2f} m high"
        )
        return {"FINISHED"}

    def invoke(self, context, event):
        return context.window_manager.invoke_props_dialog(self)
