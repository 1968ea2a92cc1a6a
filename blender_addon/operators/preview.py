"""Render Preview: the active camera at the current frame, as the backend renders the splats."""

from __future__ import annotations

import bpy
from bpy.props import IntProperty, StringProperty

from .. import prefs, preview
from ..core import errors


class SYMDRIVE_OT_render_preview(bpy.types.Operator):
    """Render the active camera at the current frame through the SymDrive backend (background splats
    and every vehicle at its keyed pose) into the image "SymDrive Preview\""""

    bl_idname = "symdrive.render_preview"
    bl_label = "Render Preview"
    bl_options = {"REGISTER", "UNDO"}

    resolution: IntProperty(
        name="Lines",
        default=0,
        min=0,
        max=4320,
        description="Preview height in pixels, the width keeping the aspect (0 = the preferences' value)",
    )
    filepath: StringProperty(
        name="Save to",
        default="",
        subtype="FILE_PATH",
        description="Also write the preview to this image file (PNG, EXR, ...); empty: only the image datablock",
    )

    def execute(self, context):
        mode, command, lines = prefs.preview_settings()
        lines = self.resolution or lines
        wm = context.window_manager
        try:
            result = preview.render_preview(context, lines, mode, command)
            if self.filepath:
                preview.core.images().write_image(bpy.path.abspath(self.filepath), result.rgb)
        except (errors.SymDriveError, ValueError, OSError) as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        shown = preview.show_in_image_editor(context, result.image) if wm is not None else False
        height, width = result.rgb.shape[:2]
        where = "" if shown or bpy.app.background else f"; open an Image Editor and pick '{result.image.name}'"
        self.report(
            {"INFO"},
            f"Preview {width}x{height} of frame {context.scene.frame_current} in "
            f"{result.export_s + result.render_s:.1f} s (export {result.export_s:.1f} s, render "
            f"{result.render_s:.1f} s, {result.backend}){where}",
        )
        return {"FINISHED"}
