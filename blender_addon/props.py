"""Add-on state stored in the .blend: ``Object.symdrive`` and ``Scene.symdrive`` property groups."""

from __future__ import annotations

import bpy
from bpy.props import (
    BoolProperty,
    EnumProperty,
    FloatProperty,
    FloatVectorProperty,
    IntProperty,
    PointerProperty,
    StringProperty,
)

from .core import scene as scene_pkg

ROLES = [
    ("NONE", "None", "Not a SymDrive object"),
    ("SPLATS", "Splats", "A 3DGS splat cloud (background or part of a vehicle)"),
    ("MESH", "Vehicle mesh", "Mesh geometry of a vehicle"),
    ("ACTOR", "Actor", "Root empty of a vehicle: its transform is the vehicle pose"),
]
KINDS = [
    ("inserted", "Inserted", "A vehicle added to the reconstruction"),
    ("existing", "Existing", "A vehicle that is part of the reconstruction"),
]


def _flip_update(self, context):
    from . import actors  # imported here: actors imports this module

    actors.apply_forward_flip(self.id_data)


class SymDriveObjectSettings(bpy.types.PropertyGroup):
    role: EnumProperty(name="Role", items=ROLES, default="NONE")
    # splat clouds: the PLY stays on disk; the .blend keeps a light preview and this reference
    ply_path: StringProperty(name="Splat PLY", subtype="FILE_PATH")
    ply_sha256: StringProperty(name="PLY SHA-256", description="Content hash of the PLY at import")
    splat_count: IntProperty(name="Splats in file", min=0)
    display_count: IntProperty(name="Splats shown", min=0)
    sh_degree: IntProperty(name="SH degree", min=0, max=3)
    # actors (vehicle root empties)
    actor_id: StringProperty(name="Actor id", description="Stable id written to the scene package")
    kind: EnumProperty(name="Kind", items=KINDS, default="inserted")
    instance_id: IntProperty(name="Instance id", min=0, description="Id of this actor in mask id maps")
    wlh: FloatVectorProperty(name="Size (w, l, h)", size=3, min=0.0, unit="LENGTH")
    ground_offset: FloatProperty(
        name="Ground offset",
        unit="LENGTH",
        description="Height of the actor origin above the ground it stands on",
    )
    flip_forward: BoolProperty(
        name="Flip forward",
        default=False,
        update=_flip_update,
        description="Turn the asset 180 degrees about Z (asset faces -X)",
    )
    flip_applied: BoolProperty(
        default=False, options={"HIDDEN"}, description="Whether the children currently carry the flip"
    )
    mesh_path: StringProperty(name="Mesh file", subtype="FILE_PATH")
    recorded_poses: StringProperty(
        name="Recorded poses",
        options={"HIDDEN"},
        description="An existing actor's track as the drive recorded it (JSON, see recorded.py): "
        "export compares its poses with it",
    )
    shadow_path: StringProperty(
        name="Shadow layer",
        subtype="FILE_PATH",
        description="An existing actor's learnt ground shadow (its reconstruction's shadow layer): exported with it, "
        "so its shadow goes where it goes",
    )
    tracked_poses: StringProperty(
        name="Tracked poses",
        options={"HIDDEN"},
        description="An existing actor's boxes as the tracker gave them, when a reconstruction refined its "
        "poses (JSON, as recorded poses): exported with it, so a later refinement starts from them",
    )
    # cameras
    export: BoolProperty(name="Export", default=True, description="Export this camera in scene packages")


class SymDriveSceneSettings(bpy.types.PropertyGroup):
    background: PointerProperty(
        name="Background splats",
        type=bpy.types.Object,
        description="Splat cloud whose frame the exported poses are relative to",
    )
    package_name: StringProperty(name="Package name", default="scene")
    export_dir: StringProperty(name="Export folder", subtype="DIR_PATH", default="//scene_package")
    lateral_offsets: StringProperty(
        name="Lateral offsets (m)",
        default="",
        description="Comma-separated camera offsets for restoration, e.g. -1.5, 1.5",
    )
    harmonize: BoolProperty(name="Harmonize inserted vehicles", default=True)
    finetune: BoolProperty(name="Fine-tune inserted vehicles", default=False)
    shadow_ratio: FloatProperty(
        name="Shadow ratio",
        default=scene_pkg.DEFAULT_SHADOW_RATIO,
        min=0.0,
        max=1.0,
        description="Fraction of its light the ground keeps in an inserted vehicle's shadow "
        "(skylight over sun plus sky); used when the scene has a sun lamp",
    )
    write_masks: BoolProperty(name="Render masks", default=True)
    copy_assets: BoolProperty(name="Copy assets into the package", default=False)
    curve: PointerProperty(name="Path curve", type=bpy.types.Object, poll=lambda self, ob: ob.type == "CURVE")
    speed: FloatProperty(name="Speed (m/s)", default=10.0, min=0.0, unit="VELOCITY")


classes = (SymDriveObjectSettings, SymDriveSceneSettings)


def register_properties() -> None:
    bpy.types.Object.symdrive = PointerProperty(type=SymDriveObjectSettings)
    bpy.types.Scene.symdrive = PointerProperty(type=SymDriveSceneSettings)


def unregister_properties() -> None:
    del bpy.types.Scene.symdrive
    del bpy.types.Object.symdrive
