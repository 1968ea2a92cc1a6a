"""Cycles on the CPU: one call renders a camera pose to colour, z-depth and object ids.

Everything comes from one multilayer EXR per render (read back with OpenImageIO, all of its
parts: Blender 5.0 writes each pass as a part of its own): the denoised combined pass (linear),
the Z pass and the object-index pass. Cycles writes Z and object index from a single sample per
pixel, so ids are exact and depth is not blended at edges. Colour is converted
to display sRGB here ("Standard" view, no look).
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import bpy
import numpy as np
from mathutils import Matrix

from symdrive_core import conventions

from . import compat
from .quiet import quiet_stdout

SKY_DEPTH = 1e9  # Cycles writes ~1e10 where a ray escapes to the sky


def setup_cycles(width: int, height: int, samples: int, seed: int = 0, threads: int = 2):
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.cycles.use_adaptive_sampling = True
    scene.cycles.adaptive_threshold = 0.02
    scene.cycles.use_denoising = True
    scene.cycles.denoiser = "OPENIMAGEDENOISE"
    scene.cycles.seed = seed
    scene.cycles.max_bounces = 4
    scene.cycles.diffuse_bounces = 2
    scene.cycles.glossy_bounces = 2
    scene.cycles.transmission_bounces = 2
    scene.cycles.caustics_reflective = False
    scene.cycles.caustics_refractive = False
    scene.render.threads_mode = "FIXED"
    scene.render.threads = threads
    scene.render.resolution_x = width
    scene.render.resolution_y = height
    scene.render.resolution_percentage = 100
    scene.render.film_transparent = False
    compat.set_multilayer_exr(scene.render.image_settings)
    layer = scene.view_layers[0]
    layer.use_pass_z = True
    layer.use_pass_object_index = True


LENS_MM = 24.0  # the built-in street's lens on a 36 mm sensor


def make_camera(lens_mm: float = LENS_MM, sensor_mm: float = 36.0):
    cam = bpy.data.cameras.new("front")
    cam.lens = lens_mm
    cam.sensor_width = sensor_mm
    cam.sensor_fit = "AUTO"
    cam.clip_start = 0.05
    cam.clip_end = 1000.0
    obj = bpy.data.objects.new("front", cam)
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.scene.camera = obj
    return obj


def camera_K(cam_obj) -> np.ndarray:
    scene, cam = bpy.context.scene, cam_obj.data
    return conventions.blender_intrinsics(
        scene.render.resolution_x, scene.render.resolution_y, cam.lens, cam.sensor_width, cam.sensor_height,
        cam.sensor_fit, cam.shift_x, cam.shift_y, scene.render.pixel_aspect_x, scene.render.pixel_aspect_y)


def _read_exr(path: Path) -> dict[str, np.ndarray]:
    """Every channel of every part of a (multipart) EXR by name. Up to 4.5 Blender writes a
    multilayer EXR as one part; 5.0 writes one part per pass unless the file is interleaved."""
    import OpenImageIO as oiio

    out: dict[str, np.ndarray] = {}
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise OSError(f"cannot read {path}: {oiio.geterror()}")
    try:
        subimage = 0
        while inp.seek_subimage(subimage, 0):
            names = list(inp.spec().channelnames)
            data = np.asarray(inp.read_image(oiio.FLOAT), dtype=np.float32).reshape(
                inp.spec().height, inp.spec().width, len(names))
            out.update({n: data[:, :, i] for i, n in enumerate(names)})
            subimage += 1
    finally:
        inp.close()
    return out


def _pass(ch: dict, suffixes: tuple[str, ...]) -> np.ndarray:
    for s in suffixes:
        for name, v in ch.items():
            if name.endswith(s):
                return v
    raise KeyError(f"render has none of the passes {suffixes}: {sorted(ch)}")


def render(cam_obj, c2w_opencv: np.ndarray) -> dict[str, np.ndarray]:
    """Render from an OpenCV camera pose: ``rgb`` sRGB [H,W,3], ``depth`` OpenCV z in metres
    [H,W] (0 = sky), ``index`` object pass index [H,W] int, ``alpha`` [H,W] (the pixel's
    coverage by objects that are not holdouts)."""
    cam_obj.matrix_world = Matrix(conventions.opencv_camera_to_blender(c2w_opencv).tolist())
    scene = bpy.context.scene
    with tempfile.TemporaryDirectory(prefix="symdrive_cycles_") as tmp:
        scene.render.filepath = str(Path(tmp) / "frame.exr")
        with quiet_stdout():
            bpy.ops.render.render(write_still=True)
        ch = _read_exr(Path(scene.render.filepath))
    rgb = np.stack([_pass(ch, (f"Combined.{c}",)) for c in "RGB"], -1)
    depth = _pass(ch, ("Depth.Z",)).copy()
    depth[~(depth < SKY_DEPTH)] = 0.0
    index = np.rint(_pass(ch, ("IndexOB.X", "IndexOB.R", "Object Index.X"))).astype(np.int32)
    alpha = _pass(ch, ("Combined.A",))
    return {"rgb": conventions.linear_to_srgb(rgb).astype(np.float32), "linear": rgb, "depth": depth, "index": index,
            "alpha": alpha}
