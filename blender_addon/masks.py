"""Exact per-actor masks rendered by Cycles, the object index written as the pixel value.

Masks are rendered in a temporary scene that holds only stand-ins of the actors' geometry and a
camera, so nothing else in the artist's scene occludes them and none of its settings change.
Each stand-in shares its source's data and modifiers but has no parent, animation or
constraints: its world matrix is copied from the source after ``frame_set``, the same evaluated
state the exported poses come from. One sample, a box filter of minimal width and an opaque
override material that emits each object's pass index make every pixel's value the id of the
surface under its centre. The id travels in the Combined pass of a plain float EXR, which every
Blender from 4.2 to 5.2 writes the same way (Blender 5.0 no longer writes extra passes such as
the object index into the render's multilayer EXR).

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

from . import actors, compat, quiet

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
        r.use_compositing, r.use_sequencer = False, False
        compat.set_float_exr(r.image_settings)
        scene.view_settings.view_transform, scene.view_settings.look = "Standard", "None"
        scene.view_settings.exposure, scene.view_settings.gamma = 0.0, 1.0
        self.material = index_material("SymDrive mask override")
        scene.view_layers[0].material_override = self.material

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
        # Cycles' persistent data keeps a depsgraph of this scene in the render engine; freed with
        # the scene still there (turning it off frees it), so no later render reuses a stale one.
        self.scene.render.use_persistent_data = False
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
        with quiet.quiet_output():
            bpy.ops.render.render(write_still=True, scene=self.scene.name)
        return read_index_image(path)

    def render(self, depsgraph, camera: bpy.types.Object, present: list[bpy.types.Object]):
        """(id map [H, W] int32 of visible instance ids, {root: amodal bool mask [H, W]})."""
        self._place(depsgraph, camera)
        ids = self._render_ids(set(present))
        if len(present) == 1:
            return ids, {present[0]: ids == present[0].symdrive.instance_id}
        amodal = {root: self._render_ids({root}) == root.symdrive.instance_id for root in present}
        return ids, amodal


def index_material(name: str) -> bpy.types.Material:
    """An opaque material emitting its object's pass index (the id) with no shading."""
    mat = bpy.data.materials.new(name)
    tree = compat.material_node_tree(mat)
    nodes, links = tree.nodes, tree.links
    nodes.clear()
    info = nodes.new("ShaderNodeObjectInfo")
    emit = nodes.new("ShaderNodeEmission")
    out = nodes.new("ShaderNodeOutputMaterial")
    emit.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    links.new(info.outputs["Object Index"], emit.inputs["Strength"])
    links.new(emit.outputs["Emission"], out.inputs["Surface"])
    return mat


def read_index_image(path: Path) -> np.ndarray:
    """The ids of an index render (red channel of a float EXR) as integers [H, W]."""
    import OpenImageIO as oiio  # bundled with Blender

    buf = oiio.ImageBuf(str(path))
    if buf.has_error or buf.spec().nchannels < 1:
        raise RuntimeError(f"{path}: cannot read the index render: {buf.geterror()}")
    pixels = np.asarray(buf.get_pixels(oiio.FLOAT))
    return np.rint(pixels[:, :, 0]).astype(np.int32)
