"""A scene package's existing actors (the vehicles the drive recorded) as editable Blender actors.

Each becomes an actor like an imported vehicle, keyed on its poses (hidden where it has none),
wearing its splat PLY or mesh, or, before reconstruction, a wire box of its ``wlh``. Its id,
instance id and recorded track are kept, so an export writes what the artist changed as an edit
of the recording (``recorded_poses``) rather than as a new vehicle.
"""

from __future__ import annotations

from pathlib import Path

import bpy
import numpy as np
from mathutils import Matrix

from . import actors, keyframes, mesh_import, recorded, reference_frame, splat_objects
from .core import errors


def import_existing(context, manifest, *, max_points: int = 0) -> list[bpy.types.Object]:
    """Build every existing actor of ``manifest``, keyed from the scene's start frame; on any error
    nothing is left behind and ``InputError`` is raised."""
    scene = context.scene
    existing = [a for a in manifest.actors if a.kind == "existing"]
    _check_free(scene, existing)
    bg = np.array(reference_frame.background_matrix(scene))
    frames = range(scene.frame_start, scene.frame_start + len(manifest.frames))
    roots: list[bpy.types.Object] = []
    try:
        for actor in existing:
            roots.append(build_existing(context, manifest, actor, bg, frames, max_points))
    except BaseException:
        for root in roots:
            _remove(root)
        raise
    return roots


def _check_free(scene, existing) -> None:
    """The package's ids must stay the actors' ids (the export writes them): refuse ids already used."""
    present = actors.all_actors(scene)
    ids = {ob.symdrive.actor_id for ob in present}
    instance_ids = {ob.symdrive.instance_id for ob in present}
    for a in existing:
        if a.id in ids:
            raise errors.InputError(a.id, "an actor with this id is already in the scene (imported before?)", "id")
        if a.instance_id in instance_ids:
            raise errors.InputError(a.id, f"instance id {a.instance_id} is taken by another actor", "instance_id")


def build_existing(context, manifest, actor, bg: np.ndarray, frames, max_points: int = 0) -> bpy.types.Object:
    """One existing actor: its root keyed on ``actor.poses`` at ``frames``, its parts, its recorded
    track and, when a reconstruction refined it, its tracked boxes; its learnt shadow layer, if any."""
    collection = context.collection
    root = bpy.data.objects.new(actor.id, None)
    root.empty_display_type, root.empty_display_size = "ARROWS", 1.0
    collection.objects.link(root)
    s = root.symdrive
    s.role, s.actor_id, s.kind, s.instance_id = "ACTOR", actor.id, "existing", actor.instance_id
    try:
        s.mesh_path = str(manifest.resolve(actor.mesh)) if actor.mesh else ""
        for part in _parts(manifest, actor, collection, max_points):
            part.parent = root
            part.matrix_parent_inverse = Matrix.Identity(4)
        actors.measure_and_ground(root, actor.wlh)
        _key_track(root, actor.poses, bg, frames)
        s.recorded_poses = recorded.encode(frames[0], actor.recorded_poses or actor.poses)
        if actor.tracked_poses is not None:
            s.tracked_poses = recorded.encode(frames[0], actor.tracked_poses)
        s.shadow_path = str(manifest.resolve(actor.shadow)) if actor.shadow else ""
    except BaseException:
        _remove(root)
        raise
    return root


def _remove(root: bpy.types.Object) -> None:
    for ob in (*root.children_recursive, root):
        bpy.data.objects.remove(ob, do_unlink=True)


def _parts(manifest, actor, collection, max_points: int):
    """What shows the actor, one part at a time (each is parented before the next is read, so a
    failure leaves nothing unowned): its splats and its mesh, or its box while it has neither."""
    if actor.splats:
        yield splat_objects.import_splat_object(
            manifest.resolve(actor.splats), collection, name=f"{actor.id} splats", max_points=max_points
        )
    if actor.mesh:
        path = manifest.resolve(actor.mesh)
        new = mesh_import.import_mesh(path, *package_axes(path))
        for ob in new:
            if ob.type == "MESH":
                ob.symdrive.role = "MESH"
        yield from [ob for ob in new if ob.parent not in new]
    if not (actor.splats or actor.mesh):
        yield proxy_box(f"{actor.id} box", actor.wlh, collection)


def package_axes(path: Path) -> tuple[str, str]:
    """(up, forward) of a package's mesh file, as the backend reads it: the actor frame, glTF's +Y up."""
    return ("Y", "X") if path.suffix.lower() in mesh_import.GLTF_SUFFIXES else ("Z", "X")


def proxy_box(name: str, wlh, collection) -> bpy.types.Object:
    """A wire box of size ``(w, l, h)`` centred on the actor origin: a vehicle not yet reconstructed."""
    w, l, h = (0.5 * float(v) for v in wlh)
    verts = [(x, y, z) for x in (-l, l) for y in (-w, w) for z in (-h, h)]
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(verts, [], quads)
    mesh.update()
    ob = bpy.data.objects.new(name, mesh)
    ob.display_type = "WIRE"
    ob.symdrive.role = "MESH"
    collection.objects.link(ob)
    return ob


def _key_track(root, poses, bg: np.ndarray, frames) -> None:
    """Key the root where the actor has a pose and its presence everywhere, as package poses are keyed."""
    keyed = [(f, bg @ p.matrix()) for f, p in zip(frames, poses, strict=True) if p is not None]
    if keyed:
        keyframes.key_world_poses(root, [f for f, _ in keyed], [M for _, M in keyed])
    keyframes.key_presence(root, frames, [p is not None for p in poses])
