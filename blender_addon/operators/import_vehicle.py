"""File > Import > 3DRealCar Vehicle: mesh and/or splats under one actor empty, on the ground."""

from __future__ import annotations

from pathlib import Path

import bpy
from bpy.props import BoolProperty, EnumProperty, StringProperty
from bpy_extras.io_utils import ImportHelper
from mathutils import Matrix

from .. import actors, mesh_import, prefs, splat_objects
from ..core import errors
from ..props import KINDS

AXIS_ITEMS = [("AUTO", "Automatic", "+Y up and +Z forward for glTF; +Z up and +X forward otherwise")] + [
    (key, key.replace("NEGATIVE_", "-"), f"The file's {key.replace('NEGATIVE_', '-')} axis")
    for key in mesh_import.AXES
]


def build_vehicle(
    context,
    path: Path,
    splat_path: Path | None,
    *,
    actor_id: str = "",
    kind: str = "inserted",
    flip_forward: bool = False,
    up_axis: str = "AUTO",
    forward_axis: str = "AUTO",
    max_points: int = 0,
) -> bpy.types.Object:
    """Create the actor; on any error nothing is left behind and ``InputError`` is raised."""
    scene, collection = context.scene, context.collection
    splat_files = [splat_path] if splat_path else []
    mesh_file = None
    if mesh_import.is_splat_ply(path):
        splat_files.insert(0, path)
    else:
        mesh_file = path
    wlh_file = path.parent / "wlh.json"
    wlh = actors.read_wlh_file(wlh_file) if wlh_file.is_file() else None

    created: list[bpy.types.Object] = []
    try:
        # the root first, so it gets the actor id as its name
        aid = actors.unique_actor_id(scene, actor_id or path.stem)
        root = bpy.data.objects.new(aid, None)
        created.append(root)
        root.empty_display_type = "ARROWS"
        root.empty_display_size = 1.0
        collection.objects.link(root)
        root.location = scene.cursor.location
        s = root.symdrive
        s.role = "ACTOR"
        s.actor_id = aid
        s.kind = kind
        s.instance_id = actors.next_instance_id(scene)
        s.mesh_path = str(mesh_file.resolve()) if mesh_file else ""
        parts = []
        for sp in splat_files:  # read splats first: the most common broken input
            ob = splat_objects.import_splat_object(
                sp, collection, name=f"{root.name} splats", max_points=max_points
            )
            created.append(ob)
            parts.append(ob)
        if mesh_file is not None:
            new = mesh_import.import_mesh(mesh_file, up_axis, forward_axis)
            created += new
            for ob in new:
                if ob.type == "MESH":
                    ob.symdrive.role = "MESH"
            parts += [ob for ob in new if ob.parent not in new]
        for ob in parts:
            ob.parent = root
            ob.matrix_parent_inverse = Matrix.Identity(4)
        s.flip_forward = flip_forward  # re-seats the children
        if not splat_files:  # a mesh-only actor's origin is its box centre (splats fix their own)
            actors.recentre(root)
        actors.measure_and_ground(root, wlh)
    except BaseException:
        for ob in created:
            bpy.data.objects.remove(ob, do_unlink=True)
        raise
    return root


class SYMDRIVE_OT_import_vehicle(bpy.types.Operator, ImportHelper):
    """Import a 3DRealCar-style vehicle (mesh and/or splat PLY) as an actor standing at the 3D cursor"""

    bl_idname = "symdrive.import_vehicle"
    bl_label = "Import Vehicle"
    bl_options = {"REGISTER", "UNDO", "PRESET"}

    filter_glob: StringProperty(default="*.ply;*.obj;*.glb;*.gltf", options={"HIDDEN"})
    splat_filepath: StringProperty(
        name="Splat PLY",
        subtype="FILE_PATH",
        default="",
        description="Optional splat PLY to add beside a mesh",
    )
    actor_id: StringProperty(name="Actor id", default="", description="Defaults to the file name")
    kind: EnumProperty(name="Kind", items=KINDS, default="inserted")
    flip_forward: BoolProperty(
        name="Flip forward", default=False, description="The asset faces -X: turn it 180 degrees about Z"
    )
    up_axis: EnumProperty(
        name="Up axis",
        default="AUTO",
        items=AXIS_ITEMS,
        description="The file's axis that points up (Automatic: +Y for glTF, +Z otherwise)",
    )
    forward_axis: EnumProperty(
        name="Forward axis",
        default="AUTO",
        items=AXIS_ITEMS,
        description="The file's axis the vehicle's front points along (Automatic: +Z for glTF, +X otherwise)",
    )

    def execute(self, context):
        splat = Path(bpy.path.abspath(self.splat_filepath)) if self.splat_filepath else None
        try:
            root = build_vehicle(
                context,
                Path(self.filepath),
                splat,
                actor_id=self.actor_id,
                kind=self.kind,
                flip_forward=self.flip_forward,
                up_axis=self.up_axis,
                forward_axis=self.forward_axis,
                max_points=prefs.default_max_points(),
            )
        except errors.SymDriveError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        except (OSError, ValueError) as exc:
            self.report({"ERROR"}, f"{self.filepath}: cannot import vehicle: {exc}")
            return {"CANCELLED"}
        for ob in context.selected_objects:
            ob.select_set(False)
        root.select_set(True)
        context.view_layer.objects.active = root
        width, length, height = root.symdrive.wlh
        summary = f"Actor {root.symdrive.actor_id!r}: {length:.2f} m long, {width:.2f} m wide, {height:.2f} m high"
        problem = actors.size_problem(root.symdrive.wlh)
        if problem:
            self.report(
                {"WARNING"},
                f"{summary}. Not car-sized: {problem} Check the up and forward axes, "
                "or use Fit to Size (sidebar > SymDrive > Selected)",
            )
        else:
            self.report({"INFO"}, summary)
        return {"FINISHED"}
