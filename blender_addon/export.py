"""Export a Blender scene as a scene package: manifest.json (validated by the core) + masks.

Every pose is evaluated with ``frame_set`` (animation, constraints and drivers applied) and
expressed in the background splat object's frame. Cameras are written in OpenCV convention with
a per-frame K from ``conventions.blender_intrinsics``. The package is written into a temporary
sibling directory, re-read and checked by the core, and only then swapped in atomically.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import re
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import bpy
import numpy as np
from mathutils import Matrix, Vector

from . import actors, camera_math, core, masks, quiet, recorded, reference_frame
from .core import atomic, conventions, errors
from .core import scene as scene_pkg

Progress = Callable[[int, int], None]


@dataclass
class ExportOptions:
    out: Path
    frame_start: int | None = None  # Blender frames, inclusive; None = the scene's range
    frame_end: int | None = None
    write_masks: bool = True
    copy_assets: bool = False
    name: str | None = None


@dataclass
class _Actor:
    root: bpy.types.Object
    splats: str | None  # absolute paths on this machine
    mesh: str | None
    shadow: str | None = None  # a recorded vehicle's learnt shadow layer
    mesh_in_package: str | None = None  # package-relative GLB the export writes of its mesh


def _file_label(name: str) -> str:
    """``name`` as a file name: kept where it is one already, else cleaned and marked with a hash
    of the name, so two names that clean alike ("Cam 1", "Cam_1"; two non-Latin names) never
    share their files."""
    label = re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("_")
    if label == name and label not in (".", ".."):
        return label
    return f"{label or 'item'}-{hashlib.sha1(name.encode('utf-8')).hexdigest()[:8]}"


def export_cameras(scene) -> list[bpy.types.Object]:
    """The scene's cameras ticked for export; a camera a vehicle's file brought along (a glTF's
    showcase camera, parented under the vehicle) is part of the vehicle, not a sensor."""
    cams = sorted(
        (ob for ob in scene.objects
         if ob.type == "CAMERA" and ob.symdrive.export and actors.actor_of(ob) is None),
        key=lambda o: o.name,
    )
    if not cams:
        raise errors.InputError(
            scene.name, "no camera to export (add a camera or tick its SymDrive Export box)"
        )
    for cam in cams:
        if cam.data.type != "PERSP":
            raise errors.InputError(
                cam.name, f"camera type {cam.data.type} is not supported (use Perspective)", "type"
            )
    return cams


def render_size(scene) -> tuple[int, int]:
    pct = scene.render.resolution_percentage / 100.0
    return max(1, round(scene.render.resolution_x * pct)), max(1, round(scene.render.resolution_y * pct))


def camera_intrinsics(scene, cam_data, width: int, height: int) -> np.ndarray:
    return conventions.blender_intrinsics(
        width,
        height,
        cam_data.lens,
        cam_data.sensor_width,
        cam_data.sensor_height,
        cam_data.sensor_fit,
        cam_data.shift_x,
        cam_data.shift_y,
        scene.render.pixel_aspect_x,
        scene.render.pixel_aspect_y,
    )


def _collect_actors(scene) -> list[_Actor]:
    out = []
    for root in actors.all_actors(scene):
        s = root.symdrive
        splat_obj = actors.splat_asset(root)
        splats = bpy.path.abspath(splat_obj.symdrive.ply_path) if splat_obj else None
        mesh = bpy.path.abspath(s.mesh_path) if s.mesh_path else None
        if splats is None and mesh is None and not _awaits_reconstruction(root):
            raise errors.InputError(root.name, "actor has neither a splat cloud nor a mesh file", "assets")
        shadow = bpy.path.abspath(s.shadow_path) if s.kind == "existing" and s.shadow_path else None
        for path in (splats, mesh, shadow):
            if path and not os.path.isfile(path):
                raise errors.InputError(path, f"asset of actor {s.actor_id!r} not found", "assets")
        out.append(_Actor(root, splats, mesh, shadow=shadow))
    seen: dict[int, bpy.types.Object] = {}
    for a in out:
        i = a.root.symdrive.instance_id
        if i < 1:
            raise errors.InputError(a.root.name, f"instance id {i}: ids are 1 or more", "instance_id")
        if i in seen:
            raise errors.InputError(
                a.root.name,
                f"instance id {i} is {seen[i].name!r}'s too (a duplicated vehicle?): give each vehicle its own "
                "in the SymDrive sidebar",
                "instance_id",
            )
        seen[i] = a.root
    return out


def _awaits_reconstruction(root: bpy.types.Object) -> bool:
    """An existing actor without assets yet: exported with its size, the backend fits it in its box."""
    return root.symdrive.kind == "existing" and min(root.symdrive.wlh) > 0


def _sun_direction(scene, depsgraph, bg_inv: Matrix) -> np.ndarray | None:
    """Direction sunlight travels (the sun lamp's -Z) in the background frame, if the scene has a sun."""
    for ob in scene.objects:  # a vehicle's own lights (a glTF's) do not light the street
        if ob.type == "LIGHT" and ob.data.type == "SUN" and not ob.hide_render and actors.actor_of(ob) is None:
            M = ob.evaluated_get(depsgraph).matrix_world
            d = (bg_inv.to_3x3() @ M.to_3x3() @ Vector((0.0, 0.0, -1.0))).normalized()
            return np.array(d)
    return None


def _check_rigid(ob: bpy.types.Object, M: Matrix) -> None:
    """Actors keep unit scale: the backend moves their PLY rigidly, so a scaled actor would not match."""
    scale = np.array(M.to_scale())
    if not np.allclose(scale, 1.0, atol=1e-4):
        raise errors.InputError(
            ob.name,
            f"scaled by {tuple(np.round(scale, 4))}: vehicles must keep unit scale (poses are rigid)",
            "scale",
        )


class _AssetPaths:
    """Manifest paths for asset files: relative to the package, or copied into ``assets/``. A file
    of the package being replaced (re-exporting an imported package into its own folder) is carried
    into the new one under the path the package gave it."""

    def __init__(self, final_dir: Path, work_dir: Path, copy: bool):
        self.final_dir, self.work_dir, self.copy, self.done = final_dir, work_dir, copy, {}

    def __call__(self, path: str | None) -> str | None:
        if path is None:
            return None
        if path not in self.done:
            inside = _inside(path, self.final_dir)
            if inside is not None:
                _carry(Path(path), self.work_dir / inside)
                self.done[path] = inside.as_posix()
            elif self.copy:
                target = self._free(Path(path).name)
                target.parent.mkdir(exist_ok=True)
                shutil.copy2(path, target)
                self.done[path] = target.relative_to(self.work_dir).as_posix()
            else:
                try:
                    self.done[path] = Path(os.path.relpath(path, self.final_dir)).as_posix()
                except ValueError:  # another drive: keep it absolute
                    self.done[path] = Path(path).as_posix()
        return self.done[path]

    def _free(self, name: str) -> Path:
        """``assets/NN_name`` under the new package, a name neither it nor the package it replaces
        has (whose files may be carried there, and may be linked to the files of that package)."""
        n = len(self.done)
        while True:
            rel = Path("assets") / f"{n:02d}_{name}"
            if not (self.work_dir / rel).exists() and not (self.final_dir / rel).exists():
                return self.work_dir / rel
            n += 1


def _inside(path: str, folder: Path) -> Path | None:
    """``path`` relative to ``folder`` when it lies inside it, else None."""
    try:
        return Path(os.path.realpath(path)).relative_to(folder)
    except ValueError:
        return None


def _carry(source: Path, target: Path) -> None:
    """A hard link where the file system allows (no copy of a large PLY), else a copy."""
    target.parent.mkdir(parents=True, exist_ok=True)
    try:
        os.link(source, target)
    except OSError:
        shutil.copy2(source, target)


def _frame_range(scene, options: ExportOptions) -> list[int]:
    f0 = scene.frame_start if options.frame_start is None else options.frame_start
    f1 = scene.frame_end if options.frame_end is None else options.frame_end
    if f1 < f0:
        raise errors.InputError(scene.name, f"frame range {f0}:{f1} is empty", "frames")
    return list(range(f0, f1 + 1))


def _package_dir(options: ExportOptions) -> Path:
    out = Path(bpy.path.abspath(str(options.out))).resolve()
    if out.exists() and not (out / "manifest.json").is_file() and any(out.iterdir()):
        raise errors.InputError(out, "exists and is not a scene package; refusing to replace it")
    return out


def _check_still(scene, depsgraph, bg_inv: Matrix) -> None:
    """The background splat object stays where it was: every pose is exported in its frame, so
    one that moves (keyframes, a constraint, a driver) would make them disagree frame to frame."""
    bg = scene.symdrive.background
    if bg is None or bg.name not in scene.objects:
        return
    drift = np.abs(np.array(bg_inv @ bg.evaluated_get(depsgraph).matrix_world) - np.eye(4)).max()
    if drift > 1e-6:
        raise errors.InputError(bg.name, f"the background object moves (at frame {scene.frame_current}): every pose "
                                "is exported in its frame, so it must stay still; move the cameras and vehicles "
                                "instead", "matrix_world")


def _depsgraph(scene):
    """The evaluated state of ``scene`` itself, which need not be the window's scene (``headless
    --scene``): its first view layer's, as ``frame_set`` updated it."""
    if bpy.context.scene == scene:
        return bpy.context.evaluated_depsgraph_get()
    return scene.view_layers[0].depsgraph


def _camera_frame(scene, depsgraph, cam, bg_inv: Matrix, width: int, height: int) -> scene_pkg.CameraFrame:
    """A camera's scale does not change what it sees: it is dropped, the rotation re-orthonormalised.
    A mirrored camera (a negative scale) sees the mirror image, which no pose can say: refused."""
    ev = cam.evaluated_get(depsgraph)
    if ev.matrix_world.to_3x3().determinant() < 0:
        raise errors.InputError(cam.name, f"mirrored by a negative scale at frame {scene.frame_current}: a camera's "
                                "image cannot be mirrored", "scale")
    c2w = conventions.blender_camera_to_opencv(reference_frame.rigid(bg_inv @ ev.matrix_world))
    return scene_pkg.CameraFrame(
        camera_intrinsics(scene, ev.data, width, height), c2w, conventions.invert_rigid(c2w)
    )


def _in_rendered_collection(scene, ob) -> bool:
    """Whether a collection holding ``ob`` renders: one reached from the scene's through
    collections none of which is disabled in renders or excluded from the view layer."""

    def renders(layer, above: bool) -> bool:
        here = above and not layer.exclude and not layer.collection.hide_render
        return (here and ob.name in layer.collection.objects) or any(renders(c, here) for c in layer.children)

    return renders(scene.view_layers[0].layer_collection, True)


def _actor_pose(scene, depsgraph, root, bg_inv: Matrix) -> scene_pkg.Pose | None:
    """The asset frame's pose in the background frame; None while the actor is disabled in
    renders (itself, or every collection it is in)."""
    ev = root.evaluated_get(depsgraph)
    if ev.hide_render or not _in_rendered_collection(scene, root):
        return None
    _check_rigid(root, ev.matrix_world)
    return scene_pkg.Pose.from_matrix(
        reference_frame.rigid(bg_inv @ ev.matrix_world @ actors.asset_frame(root))
    )


def export_scene(scene: bpy.types.Scene, options: ExportOptions, progress: Progress | None = None):
    """Write the package to ``options.out`` (replacing it atomically) and return the loaded manifest."""
    frame_numbers = _frame_range(scene, options)
    cameras = export_cameras(scene)
    actor_list = _collect_actors(scene)
    offsets = camera_math.parse_offsets(scene.symdrive.lateral_offsets)
    width, height = render_size(scene)
    out = _package_dir(options)

    cam_frames = {cam: [] for cam in cameras}
    poses = {a.root: [] for a in actor_list}
    mask_entries, id_maps = [], []
    renderer = (
        masks.MaskRenderer(scene, [a.root for a in actor_list], width, height)
        if options.write_masks and actor_list
        else None
    )
    original_frame = scene.frame_current
    try:
        scene.frame_set(frame_numbers[0])  # poses are in the background's frame where the export starts
        depsgraph = _depsgraph(scene)
        bg_inv = reference_frame.background_matrix(scene, depsgraph).inverted()
        sun = _sun_direction(scene, depsgraph, bg_inv)
        with atomic.atomic_directory(out) as work:
            with renderer or contextlib.nullcontext():
                for i, f in enumerate(frame_numbers):
                    scene.frame_set(f)
                    depsgraph = _depsgraph(scene)
                    _check_still(scene, depsgraph, bg_inv)
                    for cam in cameras:
                        cam_frames[cam].append(_camera_frame(scene, depsgraph, cam, bg_inv, width, height))
                    for a in actor_list:
                        poses[a.root].append(_actor_pose(scene, depsgraph, a.root, bg_inv))
                    present = [a.root for a in actor_list if poses[a.root][-1] is not None]
                    if renderer and present:
                        _write_masks(work, renderer, depsgraph, cameras, present, i, mask_entries, id_maps)
                    if progress:
                        progress(i + 1, len(frame_numbers))
            asset = _AssetPaths(out, work, options.copy_assets)
            for a in actor_list:
                if a.mesh is not None:  # the geometry as Blender shows it, in the actor's frame
                    a.mesh_in_package = write_actor_glb(a.root, work)
            inserted = any(a.root.symdrive.kind == "inserted" for a in actor_list)
            fps = scene.render.fps / scene.render.fps_base
            manifest = scene_pkg.Manifest(
                name=options.name or scene.symdrive.package_name or scene.name,
                frames=[
                    scene_pkg.Frame(i, (f - frame_numbers[0]) / fps) for i, f in enumerate(frame_numbers)
                ],
                cameras=[scene_pkg.Camera(cam.name, width, height, cam_frames[cam]) for cam in cameras],
                actors=[_manifest_actor(a, poses[a.root], asset, frame_numbers) for a in actor_list],
                background_splats=asset(_background_ply(scene)),
                masks=mask_entries,
                id_maps=id_maps,
                effects=scene_pkg.Effects(
                    lateral_offsets=offsets,
                    harmonize=inserted and scene.symdrive.harmonize,
                    finetune=inserted and scene.symdrive.finetune,
                    shadows=sun is not None,
                    sun_direction=sun,
                    shadow_ratio=scene.symdrive.shadow_ratio if sun is not None else None,
                ),
            )
            manifest.save(work / "manifest.json")
            # The core's own check; without copied assets the package names the user's own files
            # outside it, which the user's later runs read with --allow-external-assets.
            external = not options.copy_assets
            scene_pkg.check_files(scene_pkg.load_manifest(work / "manifest.json", allow_external=external))
    finally:
        scene.frame_set(original_frame)
    return scene_pkg.load_manifest(out / "manifest.json", allow_external=not options.copy_assets)


def _manifest_actor(a: _Actor, poses, asset: _AssetPaths, frame_numbers) -> scene_pkg.Actor:
    s = a.root.symdrive
    wlh = np.array(s.wlh) if min(s.wlh) > 0 else None
    recorded_poses = tracked_poses = None
    if s.kind == "existing" and s.recorded_poses:
        poses, recorded_poses = recorded.against_recorded(
            poses, recorded.at_frames(s.recorded_poses, frame_numbers)
        )
    if s.kind == "existing" and s.tracked_poses:
        tracked_poses = recorded.at_frames(s.tracked_poses, frame_numbers)
    return scene_pkg.Actor(
        id=s.actor_id,
        kind=s.kind,
        splats=asset(a.splats),
        mesh=a.mesh_in_package or asset(a.mesh),
        poses=poses,
        wlh=wlh,
        instance_id=s.instance_id,
        recorded_poses=recorded_poses,
        tracked_poses=tracked_poses,
        shadow=asset(a.shadow),
    )


def _background_ply(scene) -> str | None:
    bg = scene.symdrive.background
    if bg is None or bg.name not in scene.objects or not bg.symdrive.ply_path:
        return None
    return bpy.path.abspath(bg.symdrive.ply_path)


def _write_masks(work: Path, renderer, depsgraph, cameras, present, index, mask_entries, id_maps) -> None:
    images = core.images()
    for cam in cameras:
        ids, amodal = renderer.render(depsgraph, cam, present)
        folder = Path("masks") / _file_label(cam.name)
        (work / folder).mkdir(parents=True, exist_ok=True)
        id_path = (folder / f"{index:05d}_ids.png").as_posix()
        images.write_id_map(work / id_path, ids)
        id_maps.append(
            scene_pkg.IdMap(
                cam.name, index, id_path, {r.symdrive.instance_id: r.symdrive.actor_id for r in present}
            )
        )
        for root in present:
            stem = (folder / f"{index:05d}_{_file_label(root.symdrive.actor_id)}").as_posix()
            images.write_mask(work / f"{stem}_amodal.png", amodal[root].astype(np.float32))
            images.write_mask(
                work / f"{stem}_visible.png", (ids == root.symdrive.instance_id).astype(np.float32)
            )
            mask_entries.append(
                scene_pkg.MaskEntry(
                    cam.name, index, root.symdrive.actor_id, f"{stem}_amodal.png", f"{stem}_visible.png"
                )
            )


def write_actor_glb(root: bpy.types.Object, work: Path) -> str:
    """Write an actor's mesh geometry as ``assets/<actor id>/mesh.glb`` and return that path.

    Blender's own glTF exporter writes the meshes (modifiers applied, materials and their base
    colour included) in the actor's asset frame: X forward, Z up, origin at the actor's origin
    (its box centre). The coordinates are stored as they are (no conversion to glTF's Y-up), the
    same frame as a 3DRealCar OBJ, with identity node transforms. Temporary copies of the evaluated
    meshes carry the transform, so nothing in the artist's scene changes.
    """
    rel = f"assets/{_file_label(root.symdrive.actor_id)}/mesh.glb"
    target = work / rel
    target.parent.mkdir(parents=True, exist_ok=True)
    context = bpy.context
    depsgraph = context.evaluated_depsgraph_get()
    to_asset = actors.asset_world_matrix(root.evaluated_get(depsgraph)).inverted()
    parts = [ob for ob in actors.mask_geometry(root) if ob.type == "MESH"]
    if not parts:
        raise errors.InputError(root.name, "mesh-only actor has no mesh to export", "assets")
    selected = list(context.selected_objects)
    active = context.view_layer.objects.active
    collection = bpy.data.collections.new("SymDrive GLB export")
    context.scene.collection.children.link(collection)
    proxies = []
    try:
        for src in parts:  # evaluated meshes (modifiers applied), their vertices in the asset frame
            ev = src.evaluated_get(depsgraph)
            mesh = bpy.data.meshes.new_from_object(ev, preserve_all_data_layers=True, depsgraph=depsgraph)
            mesh.transform(to_asset @ ev.matrix_world)
            proxy = bpy.data.objects.new(src.name, mesh)
            collection.objects.link(proxy)
            proxies.append(proxy)
        for ob in selected:
            ob.select_set(False)
        for proxy in proxies:
            proxy.select_set(True)
        context.view_layer.objects.active = proxies[0]
        addon_utils_enable("io_scene_gltf2")
        with quiet.quiet_output():
            result = bpy.ops.export_scene.gltf(
                filepath=str(target),
                export_format="GLB",
                use_selection=True,
                export_yup=True,  # glTF's own +Y up, which the core's mesh reader turns back to Z up
                export_apply=True,
                export_animations=False,
            )
        if "FINISHED" not in result or not target.is_file():
            raise errors.InputError(root.name, "Blender's glTF exporter wrote no file", "assets")
    finally:
        for proxy in proxies:
            mesh = proxy.data
            bpy.data.objects.remove(proxy, do_unlink=True)
            bpy.data.meshes.remove(mesh)
        bpy.data.collections.remove(collection)
        for ob in selected:
            if ob.name in context.view_layer.objects:
                ob.select_set(True)
        context.view_layer.objects.active = active
    return rel


def addon_utils_enable(module: str) -> None:
    import addon_utils

    addon_utils.enable(module, default_set=False)
