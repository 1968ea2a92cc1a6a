"""Exact per-actor masks rendered by Cycles through the object-index pass.

Masks are rendered in a temporary scene that holds only stand-ins of the actors' geometry and a
camera, so nothing else in the artist's scene occludes them and none of its settings change.
Each stand-in shares its source's data and modifiers but has no parent, animation or
constraints: its world matrix is copied from the source after ``frame_set``, the same evaluated
state the exported poses come from. One sample, a box filter of minimal width and an opaque
override material make every pixel's id that of the surface under its centre.

amodal mask: the actor rendered alone. visible mask: the actor's pixels with all present
actors rendered together (other actors occlude it). The visible render is also the id map.
"""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path
from typing import Self

import bpy
import numpy as np

from . import actors

NEAR, FAR = 0.01, 1.0e5  # the backend's near plane; far enough for any street


class MaskRenderer:
    """Context manager owning the temporary scene; call :meth:`render` once per camera and frame."""

    def __init__(self, source: bpy.types.Scene, roots: list[bpy.types.Object], width: int, height: int):
        self.source, self.roots, self.width, self.height = source, roots, width, height

    def __enter__(self) -> Self:
        self._tmp = Path(tempfile.mkdtemp(prefix="symdrive-masks-"))
        self.scene = scene = bpy.data.scenes.new("SymDrive masks")
        scene.render.engine = "CYCLES"
        cycles = scene.cycles
        cycles.device = "CPU"
        cycles.samples, cycles.use_adaptive_sampling, cycles.use_denoising = 1, False, False
        cycles.pixel_filter_type, cycles.filter_width = "BOX", 0.01
        cycles.max_bounces, cycles.seed = 0, 0
        r = scene.render
        r.resolution_x, r.resolution_y, r.resolution_percentage = self.width, self.height, 100
        r.pixel_aspect_x, r.pixel_aspect_y = (
            self.source.render.pixel_aspect_x,
            self.source.render.pixel_aspect_y,
        )
        r.film_transparent, r.use_persistent_data = True, True
        r.image_settings.file_format, r.image_settings.color_depth = "OPEN_EXR_MULTILAYER", "32"
        layer = scene.view_layers[0]
        layer.use_pass_object_index = True
        self.material = bpy.data.materials.new("SymDrive mask override")
        layer.material_override = self.material

        self.camera = bpy.data.objects.new(
            "SymDrive mask camera", bpy.data.cameras.new("SymDrive mask camera")
        )
        scene.collection.objects.link(self.camera)
        scene.camera = self.camera
        self.collections, self.proxies = {}, []
        for root in self.roots:
            coll = bpy.data.collections.new(f"SymDrive mask {root.symdrive.actor_id}")
            scene.collection.children.link(coll)
            self.collections[root] = coll
            for src in actors.mask_geometry(root):
                proxy = src.copy()
                proxy.animation_data_clear()
                proxy.constraints.clear()
                proxy.parent = None
                proxy.hide_render = False
                proxy.pass_index = root.symdrive.instance_id
                coll.objects.link(proxy)
                self.proxies.append((src, proxy))
        return self

    def __exit__(self, *exc) -> None:
        for _, proxy in self.proxies:
            bpy.data.objects.remove(proxy, do_unlink=True)
        for coll in self.collections.values():
            bpy.data.collections.remove(coll)
        cam_data = self.camera.data
        bpy.data.objects.remove(self.camera, do_unlink=True)
        bpy.data.cameras.remove(cam_data)
        bpy.data.scenes.remove(self.scene)
        bpy.data.materials.remove(self.material)
        shutil.rmtree(self._tmp, ignore_errors=True)

    def _place(self, depsgraph, camera: bpy.types.Object) -> None:
        for src, proxy in self.proxies:
            proxy.matrix_world = src.evaluated_get(depsgraph).matrix_world.copy()
        cam_eval = camera.evaluated_get(depsgraph)
        self.camera.matrix_world = cam_eval.matrix_world.copy()
        data, src = self.camera.data, cam_eval.data
        data.type, data.lens_unit, data.lens = "PERSP", "MILLIMETERS", src.lens
        data.sensor_fit, data.sensor_width, data.sensor_height = (
            src.sensor_fit,
            src.sensor_width,
            src.sensor_height,
        )
        data.shift_x, data.shift_y = src.shift_x, src.shift_y
        data.clip_start, data.clip_end = NEAR, FAR

    def _render_ids(self, shown: set) -> np.ndarray:
        layer = self.scene.view_layers[0]
        for root, coll in self.collections.items():
            layer.layer_collection.children[coll.name].exclude = root not in shown
        path = self._tmp / "ids.exr"
        self.scene.render.filepath = str(path)
        bpy.ops.render.render(write_still=True, scene=self.scene.name)
        return read_index_pass(path)

    def render(self, depsgraph, camera: bpy.types.Object, present: list[bpy.types.Object]):
        """(id map [H, W] int32 of visible instance ids, {root: amodal bool mask [H, W]})."""
        self._place(depsgraph, camera)
        ids = self._render_ids(set(present))
        if len(present) == 1:
            return ids, {present[0]: ids == present[0].symdrive.instance_id}
        amodal = {root: self._render_ids({root}) == root.symdrive.instance_id for root in present}
        return ids, amodal


def read_index_pass(path: Path) -> np.ndarray:
    """The object-index channel of a multilayer EXR as integers [H, W]."""
    import OpenImageIO as oiio  # bundled with Blender

    buf = oiio.ImageBuf(str(path))
    names = list(buf.spec().channelnames)
    channel = next((i for i, n in enumerate(names) if n.split(".")[-2:-1] == ["IndexOB"]), None)
    if channel is None:
        raise RuntimeError(f"{path}: no object index pass among channels {names}")
    pixels = np.asarray(buf.get_pixels(oiio.FLOAT))
    return np.rint(pixels[:, :, channel]).astype(np.int32)
