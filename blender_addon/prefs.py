"""Add-on preferences (keyed by ``__package__``, so they work as an extension and as a legacy add-on)."""

from __future__ import annotations

import bpy
from bpy.props import EnumProperty, IntProperty, StringProperty

ADDON_ID = __package__


class SymDrivePreferences(bpy.types.AddonPreferences):
    bl_idname = ADDON_ID

    max_display_points: IntProperty(
        name="Viewport splat limit",
        default=2_000_000,
        min=0,
        description="Larger clouds show a fixed random subset of this many splats (0 = show all)",
    )
    preview_backend: EnumProperty(
        name="Preview backend",
        items=(
            ("AUTO", "Automatic", "In Blender's Python when symdrive_core and its renderer import there, "
             "else the symdrive command"),
            ("BLENDER", "In Blender", "Only in Blender's Python (symdrive installed into it)"),
            ("COMMAND", "symdrive command", "Only the symdrive command below"),
        ),
        default="AUTO",
    )
    symdrive_command: StringProperty(
        name="symdrive command",
        default="symdrive",
        subtype="FILE_PATH",
        description="The symdrive executable (a path, or a name on PATH) that renders previews "
        "when the renderer does not import in Blender's Python",
    )
    preview_resolution: IntProperty(
        name="Preview lines",
        default=480,
        min=16,
        max=4320,
        description="Height of the splat preview in pixels (the width keeps the scene's aspect)",
    )

    def draw(self, context):
        layout = self.layout
        layout.prop(self, "max_display_points")
        box = layout.box()
        box.label(text="Splat preview")
        for name in ("preview_backend", "symdrive_command", "preview_resolution"):
            box.prop(self, name)


def preferences() -> SymDrivePreferences | None:
    addon = bpy.context.preferences.addons.get(ADDON_ID)
    return addon.preferences if addon is not None else None


def default_max_points() -> int:
    prefs = preferences()
    return prefs.max_display_points if prefs is not None else 2_000_000


def preview_settings() -> tuple[str, str, int]:
    """(backend, symdrive command, preview lines) from the preferences, or their defaults."""
    prefs = preferences()
    if prefs is None:
        return "AUTO", "symdrive", 480
    return prefs.preview_backend, prefs.symdrive_command, prefs.preview_resolution
