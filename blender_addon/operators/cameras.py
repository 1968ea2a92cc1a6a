"""Camera rigs from a scene package: one animated Blender camera per package camera, plus
lateral-offset copies that preview the shifted views the backend restores."""

from __future__ import annotations

import bpy
import numpy as np
from bpy.props import StringProperty
from bpy_extras.io_utils import ImportHelper

from .. import camera_math, keyframes, reference_frame
from ..core import conventions, errors
from ..core import scene as scene_pkg

_LENS_PATHS = ("lens", "shift_x", "shift_y")


def _set_frame_timing(scene, manifest) -> None:
    scene.frame_end = scene.frame_start + len(manifest.frames) - 1
    if len(manifest.frames) > 1:
        dt = float(np.median(np.diff([f.timestamp for f in manifest.frames])))
        fps = max(1, round(1.0 / dt))
        scene.render.fps, scene.render.fps_base = fps, fps * dt


def _build_camera(context, cam, bg: np.ndarray, width: int, height: int) -> bpy.types.Object:
    scene = context.scene
    data = bpy.data.cameras.new(cam.name)
    obj = bpy.data.objects.new(cam.name, data)
    context.collection.objects.link(obj)
    lenses = [
        conventions.lens_from_intrinsics(
            cf.K * [[width / cam.width], [height / cam.height], [1]], width, height
        )
        for cf in cam.frames
    ]
    data.sensor_fit, data.sensor_width = "HORIZONTAL", lenses[0].sensor_width_mm
    frame_numbers = range(scene.frame_start, scene.frame_start + len(cam.frames))
    values = np.array([[x.lens_mm, x.shift_x, x.shift_y] for x in lenses])
    varying = [p for p, column in zip(_LENS_PATHS, values.T, strict=True) if np.ptp(column) > 1e-9]
    for f, row in zip(frame_numbers, values, strict=True):
        data.lens, data.shift_x, data.shift_y = row
        for p in varying:  # constant intrinsics stay unkeyed
            data.keyframe_insert(p, frame=f)
    data.lens, data.shift_x, data.shift_y = values[0]
    scene.render.pixel_aspect_x, scene.render.pixel_aspect_y = (
        lenses[0].pixel_aspect_x,
        lenses[0].pixel_aspect_y,
    )
    world = [bg @ conventions.opencv_camera_to_blender(cf.camera_to_world) for cf in cam.frames]
    keyframes.key_world_poses(obj, frame_numbers, world)
    return obj


def add_lateral_copies(camera: bpy.types.Object, offsets) -> list[bpy.types.Object]:
    """Child cameras shifted along the camera's right axis (previews; not exported as cameras)."""
    copies = []
    for off in offsets:
        obj = bpy.data.objects.new(f"{camera.name} {off:+g} m", camera.data)
        for coll in camera.users_collection:
            coll.objects.link(obj)
        obj.parent = camera
        obj.location = (off, 0.0, 0.0)  # Blender's camera x axis is OpenCV's x axis (right)
        obj.symdrive.export = False
        copies.append(obj)
    return copies


class SYMDRIVE_OT_import_camera_rig(bpy.types.Operator, ImportHelper):
    """Import the cameras of a scene package as animated Blender cameras (with lateral offset copies)"""

    bl_idname = "symdrive.import_camera_rig"
    bl_label = "Import Camera Rig"
    bl_options = {"REGISTER", "UNDO"}

    filename_ext = ".json"
    filter_glob: StringProperty(default="*.json", options={"HIDDEN"})
    lateral_offsets: StringProperty(
        name="Lateral offsets (m)",
        default="",
        description="Extra offsets, comma-separated; the package's own are always added",
    )

    def execute(self, context):
        scene = context.scene
        try:
            manifest = scene_pkg.load_manifest(self.filepath)
            bg = np.array(reference_frame.background_matrix(scene))
            offsets = sorted(
                set(manifest.effects.lateral_offsets) | set(camera_math.parse_offsets(self.lateral_offsets))
            )
            first = manifest.cameras[0]
            scene.render.resolution_x, scene.render.resolution_y = first.width, first.height
            scene.render.resolution_percentage = 100
            _set_frame_timing(scene, manifest)
            cams = [_build_camera(context, cam, bg, first.width, first.height) for cam in manifest.cameras]
        except (errors.SymDriveError, ValueError) as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        for cam in cams:
            add_lateral_copies(cam, [o for o in offsets if o != 0.0])
        scene.camera = cams[0]
        scene.symdrive.lateral_offsets = ", ".join(f"{o:g}" for o in offsets)
        resized = [c.name for c in manifest.cameras if (c.width, c.height) != (first.width, first.height)]
        if resized:
            self.report(
                {"WARNING"},
                f"Blender has one resolution per scene: cameras {', '.join(resized)} were "
                f"rescaled to {first.width}x{first.height}",
            )
        self.report({"INFO"}, f"Imported {len(cams)} camera(s) over {len(manifest.frames)} frames")
        return {"FINISHED"}
