"""Import Recorded Drive: the cameras of a reconstructed drive as animated Blender cameras, each
recorded frame shown as the camera's background image on its frame.

Reads nerfstudio ``transforms.json``, the 3DGS trainer's ``cameras.json`` and COLMAP models with
the core's own readers (``importers.nerfstudio``, ``importers.gs_trainer``: numpy only;
``importers.colmap``: pycolmap, imported only when a COLMAP model is chosen, so the add-on loads
without it), groups the views into cameras and frames as ``symdrive import`` does, and builds the
cameras with *Import Camera Rig*'s code. Poses stay in the reconstruction's frame (no ground fit,
no metric scale: ``symdrive import`` does that).
"""

from __future__ import annotations

import importlib
import json
from pathlib import Path
from types import SimpleNamespace

import bpy
import numpy as np
from bpy.props import BoolProperty, FloatProperty, StringProperty
from bpy_extras.io_utils import ImportHelper

from .. import reference_frame
from ..core import CORE, conventions, errors
from ..core import scene as scene_pkg
from .cameras import _build_camera, _set_frame_timing


def _importer(name: str):
    return importlib.import_module(f"{CORE}.importers.{name}")


DEFAULT_FPS = _importer("frames").DEFAULT_FPS  # the command line's --fps default, one value
COLMAP_FILES = ("cameras", "images", "points3D", "rigs", "frames")  # the .bin/.txt files of a model


def colmap_model(path: Path) -> Path | None:
    """The COLMAP model folder ``path`` is, or holds ``path`` (cameras.bin, images.txt, ...); else None."""
    if path.is_file() and not (path.stem in COLMAP_FILES and path.suffix in (".bin", ".txt")):
        return None
    folder = path if path.is_dir() else path.parent
    return folder if _importer("colmap").model_file(folder, "cameras").is_file() else None


def colmap_images(model: Path) -> Path:
    """Where a COLMAP project keeps its images: ``images/`` in, beside or two above the model
    (``sparse/0`` of ``colmap mapper``, ``sparse`` of ``colmap image_undistorter``)."""
    candidates = [model / "images", model.parent / "images", model.parent.parent / "images"]
    return next((c for c in candidates if c.is_dir()), candidates[1])


def read_drive(path: str | Path, images: str | Path | None = None, fps: float = DEFAULT_FPS):
    """(format, Grouped views) of a nerfstudio transforms.json, a 3DGS trainer's cameras.json or a
    COLMAP model folder."""
    path = Path(path)
    model = colmap_model(path)
    if model is not None:
        src = _importer("colmap").read_colmap(model, images or colmap_images(model), fps=fps)
        return "colmap", src.grouped
    if path.is_dir():
        path = path / ("transforms.json" if (path / "transforms.json").is_file() else "cameras.json")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise errors.InputError(path, "file not found") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise errors.InputError(path, f"not valid JSON: {exc}") from None
    frames = _importer("frames")
    if isinstance(data, dict) and "frames" in data:
        views = _importer("nerfstudio").read_views(path)[3]
        fmt = "nerfstudio"
    elif isinstance(data, list):
        model = path.parent
        if images is None and not (model / "cfg_args").is_file():
            images = model / "images"
        views = _importer("gs_trainer").read_views(model, images)
        fmt = "3dgs"
    else:
        raise errors.InputError(
            path,
            "neither a nerfstudio transforms.json (an object with 'frames') nor a "
            "3DGS trainer's cameras.json (a list); for COLMAP choose the model folder "
            "(cameras.bin or cameras.txt)",
        )
    return fmt, frames.group_views(views, fps=fps)


def _cameras(grouped):
    """Core ``Camera`` records (the type *Import Camera Rig* builds from) and the frames' timing."""
    cams = []
    for name, row in zip(grouped.cameras, grouped.table, strict=True):
        cfs = [
            scene_pkg.CameraFrame(
                v.K, v.c2w, conventions.invert_rigid(v.c2w), None if v.image is None else str(v.image)
            )
            for v in row
        ]
        cams.append(scene_pkg.Camera(name, row[0].width, row[0].height, cfs))
    timing = SimpleNamespace(frames=[scene_pkg.Frame(i, t) for i, t in enumerate(grouped.timestamps)])
    return cams, timing


def set_background_frames(camera: bpy.types.Object, images: list[str | None], frame_start: int) -> list[str]:
    """One background image per recorded frame, shown (alpha 1) on its frame only; returns the
    images that were not found."""
    data = camera.data
    data.show_background_images = True
    missing = []
    for i, path in enumerate(images):
        if path is None or not Path(path).is_file():
            missing.append(str(path))
            continue
        bg = data.background_images.new()
        bg.image = bpy.data.images.load(path, check_existing=True)
        bg.show_expanded = False
        bg.frame_method = "FIT"
        slot = len(data.background_images) - 1
        frame = frame_start + i
        for f, alpha in ((frame - 1, 0.0), (frame, 1.0), (frame + 1, 0.0)):
            if f < frame_start or f >= frame_start + len(images):
                continue
            bg.alpha = alpha
            data.keyframe_insert(f"background_images[{slot}].alpha", frame=f)
        bg.alpha = 1.0 if i == 0 else 0.0
    if data.animation_data and data.animation_data.action:
        from ..compat import action_fcurves

        for fc in action_fcurves(data.animation_data.action, data):
            if fc.data_path.startswith("background_images"):
                for kp in fc.keyframe_points:
                    kp.interpolation = "CONSTANT"
    return missing


class SYMDRIVE_OT_import_drive(bpy.types.Operator, ImportHelper):
    """Import a recorded drive (nerfstudio transforms.json, 3DGS cameras.json or a COLMAP model folder)
    as animated cameras with each recorded frame as the camera's background"""

    bl_idname = "symdrive.import_drive"
    bl_label = "Import Recorded Drive"
    bl_options = {"REGISTER", "UNDO"}

    filename_ext = ".json"
    filter_glob: StringProperty(default="*.json;*.bin;*.txt", options={"HIDDEN"})
    images_dir: StringProperty(
        name="Images folder",
        default="",
        subtype="DIR_PATH",
        description="3DGS and COLMAP: where the recorded images are (default 3DGS: cfg_args' source, else "
        "images/ beside cameras.json; COLMAP: images/ in, beside or two folders above the model)",
    )
    fps: FloatProperty(
        name="Frame rate",
        default=DEFAULT_FPS,
        min=0.1,
        max=1000.0,
        description="Frames per second when the file has no timestamps",
    )
    backgrounds: BoolProperty(name="Recorded frames as backgrounds", default=True)

    def execute(self, context):
        scene = context.scene
        try:
            fmt, grouped = read_drive(self.filepath, self.images_dir or None, self.fps)
            cams, timing = _cameras(grouped)
            bg = np.array(reference_frame.background_matrix(scene))
            first = cams[0]
            scene.render.resolution_x, scene.render.resolution_y = first.width, first.height
            scene.render.resolution_percentage = 100
            _set_frame_timing(scene, timing)
            objs = [_build_camera(context, cam, bg, first.width, first.height) for cam in cams]
        except (errors.SymDriveError, ValueError) as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        missing = []
        if self.backgrounds:
            for obj, cam in zip(objs, cams, strict=True):
                missing += set_background_frames(obj, [cf.image for cf in cam.frames], scene.frame_start)
        scene.camera = objs[0]
        if missing:
            self.report({"WARNING"}, f"{len(missing)} recorded image(s) not found, e.g. {missing[0]}")
        self.report({"INFO"}, f"Imported {len(objs)} camera(s) over {len(timing.frames)} frames ({fmt})")
        return {"FINISHED"}
