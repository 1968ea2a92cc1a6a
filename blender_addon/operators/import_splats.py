"""File > Import > 3DGS Splats (.ply)."""

from __future__ import annotations

import time

import bpy
from bpy.props import BoolProperty, FloatProperty, IntProperty, StringProperty
from bpy_extras.io_utils import ImportHelper

from .. import prefs, splat_objects
from ..core import errors


class SYMDRIVE_OT_import_splats(bpy.types.Operator, ImportHelper):
    """Import an INRIA 3DGS splat PLY as a point display (the PLY stays the source of truth)"""

    bl_idname = "symdrive.import_splats"
    bl_label = "Import 3DGS Splats"
    bl_options = {"REGISTER", "UNDO", "PRESET"}

    filename_ext = ".ply"
    filter_glob: StringProperty(default="*.ply", options={"HIDDEN"})
    max_points: IntProperty(
        name="Viewport limit",
        default=-1,
        min=-1,
        description="Show at most this many splats (0 = all, -1 = add-on preference)",
    )
    point_size: FloatProperty(
        name="Point size",
        default=1.0,
        min=0.0,
        description="Display radius as a multiple of each splat's mean scale",
    )
    as_background: BoolProperty(
        name="Use as background",
        default=True,
        description="Make this cloud the frame that exported poses are relative to",
    )

    def execute(self, context):
        limit = prefs.default_max_points() if self.max_points < 0 else self.max_points
        t0 = time.perf_counter()
        try:
            obj = splat_objects.import_splat_object(
                self.filepath, context.collection, max_points=limit, point_size=self.point_size
            )
        except errors.SymDriveError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        except (OSError, ValueError, MemoryError) as exc:
            self.report({"ERROR"}, f"{self.filepath}: cannot import: {exc}")
            return {"CANCELLED"}
        for other in context.selected_objects:
            other.select_set(False)
        obj.select_set(True)
        context.view_layer.objects.active = obj
        if self.as_background:
            context.scene.symdrive.background = obj
        s = obj.symdrive
        shown = "" if s.display_count == s.splat_count else f", showing {s.display_count}"
        self.report(
            {"INFO"},
            f"Imported {s.splat_count} splats (SH degree {s.sh_degree}{shown}) "
            f"in {time.perf_counter() - t0:.2f} s",
        )
        return {"FINISHED"}
