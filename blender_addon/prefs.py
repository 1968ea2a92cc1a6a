"""Add-on preferences (keyed by ``__package__``, so they work as an extension and as a legacy add-on)."""

from __future__ import annotations

import bpy
from bpy.props import IntProperty

ADDON_ID = __package__


class SymDrivePreferences(bpy.types.AddonPreferences):
    bl_idname = ADDON_ID

    max_display_points: IntProperty(
        name="Viewport splat limit",
        default=2_000_000,
        min=0,
        description="Larger clouds show a fixed random subset of this many splats (0 = show all)",
    )

    def draw(self, context):
        self.layout.prop(self, "max_display_points")


def preferences() -> SymDrivePreferences | None:
    addon = bpy.context.preferences.addons.get(ADDON_ID)
    return addon.preferences if addon is not None else None


def default_max_points() -> int:
    prefs = preferences()
    return prefs.max_display_points if prefs is not None else 2_000_000
