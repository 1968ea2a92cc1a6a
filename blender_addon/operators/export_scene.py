"""File > Export > SymDrive Scene Package."""

from __future__ import annotations

import time
from pathlib import Path

import bpy
from bpy.props import BoolProperty, IntProperty, StringProperty

from .. import export
from ..core import errors


def _progress(wm, i: int, n: int) -> None:
    """The progress bar, and one console line per frame (render status lines are silenced)."""
    wm.progress_update(i / n)
    print(f"SymDrive export: frame {i}/{n}", flush=True)


class SYMDRIVE_OT_export_scene(bpy.types.Operator):
    """Export cameras, vehicle poses and masks of the frame range as a scene package"""

    bl_idname = "symdrive.export_scene"
    bl_label = "Export Scene Package"
    bl_options = {"REGISTER", "UNDO"}

    directory: StringProperty(
        name="Package folder",
        subtype="DIR_PATH",
        default="",
        description="Default: the panel's export folder",
    )
    frame_start: IntProperty(name="Start frame", default=-1, description="Negative: the scene's start frame")
    frame_end: IntProperty(name="End frame", default=-1, description="Negative: the scene's end frame")
    write_masks: BoolProperty(name="Render masks", default=True)

    def execute(self, context):
        scene = context.scene
        target = self.directory or scene.symdrive.export_dir
        if not target:
            self.report({"ERROR"}, "choose a package folder")
            return {"CANCELLED"}
        options = export.ExportOptions(
            out=Path(bpy.path.abspath(target)),
            frame_start=None if self.frame_start < 0 else self.frame_start,
            frame_end=None if self.frame_end < 0 else self.frame_end,
            write_masks=self.write_masks and scene.symdrive.write_masks,
            copy_assets=scene.symdrive.copy_assets,
        )
        wm = context.window_manager
        t0 = time.perf_counter()
        wm.progress_begin(0, 1)
        try:
            manifest = export.export_scene(scene, options, progress=lambda i, n: _progress(wm, i, n))
        except (errors.SymDriveError, ValueError, OSError) as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        finally:
            wm.progress_end()
        self.report(
            {"INFO"},
            f"Exported {len(manifest.frames)} frames, {len(manifest.cameras)} camera(s), "
            f"{len(manifest.actors)} actor(s) to {manifest.root} in {time.perf_counter() - t0:.1f} s",
        )
        return {"FINISHED"}

    def invoke(self, context, event):
        if not self.directory:
            self.directory = bpy.path.abspath(context.scene.symdrive.export_dir)
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}
