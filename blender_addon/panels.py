"""The "SymDrive" tab of the 3D viewport's sidebar (N panel) and the File menu entries."""

from __future__ import annotations

import bpy

from . import actors


class _Sidebar:
    """Where every SymDrive panel lives: the 3D viewport's sidebar, tab "SymDrive"."""

    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "SymDrive"


class SYMDRIVE_PT_main(_Sidebar, bpy.types.Panel):
    bl_label = "SymDrive"
    bl_idname = "SYMDRIVE_PT_main"

    def draw(self, context):
        layout = self.layout
        settings = context.scene.symdrive
        col = layout.column(align=True)
        col.operator("symdrive.import_splats", icon="POINTCLOUD_DATA")
        col.operator("symdrive.import_vehicle", icon="AUTO")
        col.operator("symdrive.import_camera_rig", icon="CAMERA_DATA")
        col.operator("symdrive.import_drive", icon="FILE_MOVIE")
        col.operator("symdrive.import_recorded_vehicles", icon="AUTO")
        layout.prop(settings, "background")
        layout.operator("symdrive.render_preview", icon="RENDER_STILL")


class SYMDRIVE_PT_object(_Sidebar, bpy.types.Panel):
    bl_label = "Selected"
    bl_parent_id = "SYMDRIVE_PT_main"

    @classmethod
    def poll(cls, context):
        ob = context.active_object
        return ob is not None and (
            actors.actor_of(ob) is not None or ob.symdrive.role == "SPLATS" or ob.type == "CAMERA"
        )

    def draw(self, context):
        layout = self.layout
        ob = context.active_object
        root = actors.actor_of(ob)
        if root is not None:
            s = root.symdrive
            layout.prop(s, "actor_id")
            layout.prop(s, "kind")
            layout.prop(s, "flip_forward")
            layout.prop(s, "wlh")
            problem = actors.size_problem(s.wlh) if min(s.wlh) > 0 else None
            if problem:
                layout.label(text=f"Not car-sized: {problem}", icon="ERROR")
            layout.operator("symdrive.fit_vehicle_size", icon="FULLSCREEN_ENTER")
            layout.label(text=f"Instance id {s.instance_id}, ground offset {s.ground_offset:.3f} m")
            if s.recorded_poses:
                layout.label(text="Recorded vehicle: changes export as edits of its track", icon="INFO")
            if s.tracked_poses:
                layout.label(text="Poses refined from its tracks (kept on export)")
            row = layout.row(align=True)
            row.operator("symdrive.remove_vehicle", icon="HIDE_ON")
            row.operator("symdrive.shift_vehicle_keys", icon="TIME")
        elif ob.symdrive.role == "SPLATS":
            s = ob.symdrive
            layout.label(text=f"{s.splat_count} splats, SH degree {s.sh_degree}")
            if s.display_count != s.splat_count:
                layout.label(text=f"Showing {s.display_count}")
            layout.prop(s, "ply_path")
        else:
            layout.prop(ob.symdrive, "export", text="Export this camera")


class SYMDRIVE_PT_trajectory(_Sidebar, bpy.types.Panel):
    bl_label = "Trajectory"
    bl_parent_id = "SYMDRIVE_PT_main"

    def draw(self, context):
        layout = self.layout
        settings = context.scene.symdrive
        layout.operator("symdrive.key_pose", icon="KEY_HLT")
        box = layout.box()
        box.prop(settings, "curve")
        box.prop(settings, "speed")
        box.operator("symdrive.follow_curve", icon="CURVE_PATH")
        col = layout.column(align=True)
        col.operator("symdrive.import_package_poses", icon="FILE")
        col.operator("symdrive.import_sumo_fcd", icon="FILE_SCRIPT")


class SYMDRIVE_PT_export(_Sidebar, bpy.types.Panel):
    bl_label = "Export"
    bl_parent_id = "SYMDRIVE_PT_main"

    def draw(self, context):
        layout = self.layout
        settings = context.scene.symdrive
        for name in (
            "package_name",
            "export_dir",
            "lateral_offsets",
            "harmonize",
            "finetune",
            "shadow_ratio",
            "write_masks",
            "copy_assets",
        ):
            layout.prop(settings, name)
        layout.operator("symdrive.export_scene", icon="EXPORT")


def menu_import(self, context):
    self.layout.operator("symdrive.import_splats", text="3DGS Splats (.ply)")
    self.layout.operator("symdrive.import_vehicle", text="SymDrive Vehicle (.obj/.ply/.glb)")
    self.layout.operator("symdrive.import_drive", text="Recorded Drive (COLMAP / nerfstudio / 3DGS)")
    self.layout.operator("symdrive.import_recorded_vehicles", text="Recorded Vehicles (SymDrive package)")


def menu_export(self, context):
    self.layout.operator("symdrive.export_scene", text="SymDrive Scene Package")


panels = (SYMDRIVE_PT_main, SYMDRIVE_PT_object, SYMDRIVE_PT_trajectory, SYMDRIVE_PT_export)
