"""SymDrive: 3DGS splats and vehicles in, keyframed trajectories, scene packages out.

Works as a Blender 4.2+ extension (``blender_manifest.toml``) and as a legacy add-on
(``bl_info``). Submodules are imported in :func:`register`, so the bpy-free helpers
(``path_sampling``, ``camera_math``) import without Blender.
"""

bl_info = {
    "name": "SymDrive",
    "author": "SymDrive developers",
    "version": (0, 1, 0),
    "blender": (4, 2, 0),
    "location": "File > Import/Export, View3D > Sidebar > SymDrive",
    "description": "Import 3DGS splats and vehicles, keyframe them, export driving scene packages",
    "category": "Import-Export",
}

_unregister = None


def _classes():
    from . import panels, prefs, props
    from .operators import (
        cameras,
        export_scene,
        fit_size,
        import_drive,
        import_splats,
        import_vehicle,
        preview,
        recorded_vehicles,
        trajectory,
    )

    return (
        *props.classes,
        prefs.SymDrivePreferences,
        import_splats.SYMDRIVE_OT_import_splats,
        import_vehicle.SYMDRIVE_OT_import_vehicle,
        fit_size.SYMDRIVE_OT_fit_vehicle_size,
        trajectory.SYMDRIVE_OT_key_pose,
        trajectory.SYMDRIVE_OT_follow_curve,
        trajectory.SYMDRIVE_OT_import_package_poses,
        trajectory.SYMDRIVE_OT_import_sumo_fcd,
        cameras.SYMDRIVE_OT_import_camera_rig,
        import_drive.SYMDRIVE_OT_import_drive,
        recorded_vehicles.SYMDRIVE_OT_import_recorded_vehicles,
        recorded_vehicles.SYMDRIVE_OT_remove_vehicle,
        recorded_vehicles.SYMDRIVE_OT_shift_vehicle_keys,
        export_scene.SYMDRIVE_OT_export_scene,
        preview.SYMDRIVE_OT_render_preview,
        *panels.panels,
    )


def register():
    import bpy

    from . import panels, props

    global _unregister
    register_classes, _unregister = bpy.utils.register_classes_factory(_classes())
    register_classes()
    props.register_properties()
    bpy.types.TOPBAR_MT_file_import.append(panels.menu_import)
    bpy.types.TOPBAR_MT_file_export.append(panels.menu_export)


def unregister():
    import bpy

    from . import panels, props

    global _unregister
    bpy.types.TOPBAR_MT_file_export.remove(panels.menu_export)
    bpy.types.TOPBAR_MT_file_import.remove(panels.menu_import)
    props.unregister_properties()
    if _unregister is not None:
        _unregister()
        _unregister = None
