"""Editing the vehicles a drive recorded: import them from a scene package, remove them, retime them
(moving one is re-keying it, as for any vehicle)."""

from __future__ import annotations

import bpy
from bpy.props import BoolProperty, IntProperty, StringProperty
from bpy_extras.io_utils import ImportHelper

from .. import actors, existing, keyframes, prefs
from ..core import errors
from ..core import scene as scene_pkg


class SYMDRIVE_OT_import_recorded_vehicles(bpy.types.Operator, ImportHelper):
    """Import the vehicles a scene package's drive recorded (its existing actors), keyed on their
    poses from the scene's start frame, to edit them"""

    bl_idname = "symdrive.import_recorded_vehicles"
    bl_label = "Import Recorded Vehicles"
    bl_options = {"REGISTER", "UNDO"}

    filename_ext = ".json"
    filter_glob: StringProperty(default="*.json", options={"HIDDEN"})
    allow_external_assets: BoolProperty(
        name="Allow External Assets", default=False,
        description="Read asset files outside the package (a package exported without copying its assets names "
                    "your own files); off, such a package is refused, naming the field")

    def execute(self, context):
        try:
            manifest = scene_pkg.load_manifest(self.filepath, allow_external=self.allow_external_assets)
            roots = existing.import_existing(context, manifest, max_points=prefs.default_max_points())
        except errors.SymDriveError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        except (OSError, ValueError) as exc:
            self.report({"ERROR"}, f"{self.filepath}: cannot import recorded vehicles: {exc}")
            return {"CANCELLED"}
        if not roots:
            self.report({"WARNING"}, "the package has no existing (recorded) actors")
            return {"CANCELLED"}
        for ob in context.selected_objects:
            ob.select_set(False)
        for root in roots:
            root.select_set(True)
        context.view_layer.objects.active = roots[0]
        boxes = sum(1 for r in roots if actors.splat_asset(r) is None and not r.symdrive.mesh_path)
        waiting = f" ({boxes} not reconstructed yet: shown as their box)" if boxes else ""
        self.report({"INFO"}, f"Imported {len(roots)} recorded vehicle(s){waiting}")
        return {"FINISHED"}


class SYMDRIVE_OT_remove_vehicle(bpy.types.Operator):
    """Disable the selected vehicles in renders at every frame (a recorded vehicle is then exported
    as removed, its recorded track kept)"""

    bl_idname = "symdrive.remove_vehicle"
    bl_label = "Remove Vehicle"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        roots = actors.selected_actors(context, self)
        if not roots:
            return {"CANCELLED"}
        for root in roots:
            keyframes.disable_in_renders(root)
        self.report({"INFO"}, f"Removed {len(roots)} vehicle(s) from every frame")
        return {"FINISHED"}


class SYMDRIVE_OT_shift_vehicle_keys(bpy.types.Operator):
    """Retime the selected vehicles: move all their keys (poses and presence) by a number of frames"""

    bl_idname = "symdrive.shift_vehicle_keys"
    bl_label = "Shift Vehicle Keys"
    bl_options = {"REGISTER", "UNDO"}

    frames: IntProperty(name="Frames", default=1, description="Positive: later; negative: earlier")

    def execute(self, context):
        roots = actors.selected_actors(context, self)
        if not roots:
            return {"CANCELLED"}
        for root in roots:
            keyframes.shift_keys(root, self.frames)
        context.scene.frame_set(context.scene.frame_current)  # show the shifted pose now
        self.report({"INFO"}, f"Shifted the keys of {len(roots)} vehicle(s) by {self.frames} frame(s)")
        return {"FINISHED"}
