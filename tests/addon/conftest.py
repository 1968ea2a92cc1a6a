"""A factory-empty Blender session with the add-on registered, per test (real bpy, no mocks)."""

from __future__ import annotations

import pytest


@pytest.fixture
def blender():
    bpy = pytest.importorskip("bpy")
    import blender_addon

    bpy.ops.wm.read_factory_settings(use_empty=True)
    blender_addon.register()
    try:
        yield bpy
    finally:
        blender_addon.unregister()
