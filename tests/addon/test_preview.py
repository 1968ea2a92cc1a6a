"""Render Preview: the active camera at the current frame through the backend, in Blender's
Python and through the symdrive command, and one clear error when neither is there."""

import sys
from pathlib import Path

import numpy as np
import pytest

from tests.addon.scenes import two_car_scene

pytestmark = pytest.mark.blender

LINES = 24  # 32 x 24: the scene is 64 x 48


@pytest.fixture
def scene(blender, tmp_path):
    objs = two_car_scene(blender, tmp_path / "assets", n_frames=3)
    addon = blender.context.preferences.addons.new()  # registered by hand: give it its preferences
    addon.module = "blender_addon"
    return blender, objs, addon.preferences


@pytest.fixture
def backend():
    """The renderer's own dependencies (absent in the bpy 5.2 venv, where these tests skip)."""
    pytest.importorskip("torch")
    pytest.importorskip("numba")


def _pixels(image):
    w, h = image.size
    px = np.empty(w * h * 4, dtype=np.float32)
    image.pixels.foreach_get(px)
    return px.reshape(h, w, 4)[::-1, :, :3]


def test_in_process_preview_shows_the_cars_over_the_background(scene, backend, tmp_path):
    bpy, objs, prefs = scene
    prefs.preview_backend = "BLENDER"
    saved = tmp_path / "preview.png"
    assert bpy.ops.symdrive.render_preview(resolution=LINES, filepath=str(saved)) == {"FINISHED"}
    image = bpy.data.images["SymDrive Preview"]
    assert tuple(image.size) == (32, 24)
    with_cars = _pixels(image)
    assert with_cars.max() > 0.05 and saved.is_file()
    for car in objs["cars"]:  # the same frame without the vehicles: the cars' pixels change
        car.hide_render = True
    assert bpy.ops.symdrive.render_preview(resolution=LINES) == {"FINISHED"}
    assert len([im for im in bpy.data.images if im.name.startswith("SymDrive Preview")]) == 1  # reused
    background = _pixels(bpy.data.images["SymDrive Preview"])
    changed = np.abs(with_cars - background).max(axis=2) > 0.05
    assert 0 < changed.mean() < 0.9
    # only the preview changed: the scene's cameras and frame are as they were
    assert objs["camera"].symdrive.export and bpy.context.scene.frame_current == 1


@pytest.mark.skipif(sys.platform == "win32", reason="the wrapper is a POSIX script")
def test_the_symdrive_command_renders_the_same_preview(scene, backend, tmp_path):
    bpy, _, prefs = scene
    prefs.preview_backend = "BLENDER"
    assert bpy.ops.symdrive.render_preview(resolution=LINES) == {"FINISHED"}
    in_process = _pixels(bpy.data.images["SymDrive Preview"])
    root = str(Path(__file__).resolve().parents[2])
    wrapper = tmp_path / "bin" / "symdrive"
    wrapper.parent.mkdir()
    wrapper.write_text(f"#!{sys.executable}\nimport sys\nsys.path.insert(0, {root!r})\n"
                       "from symdrive_core.cli import main\nsys.exit(main())\n")
    wrapper.chmod(0o755)
    prefs.preview_backend, prefs.symdrive_command = "COMMAND", str(wrapper)
    assert bpy.ops.symdrive.render_preview(resolution=LINES) == {"FINISHED"}
    via_command = _pixels(bpy.data.images["SymDrive Preview"])
    assert np.abs(via_command - in_process).max() <= 1.5 / 255  # the command's PNG: 8 bits


def test_no_backend_gives_one_error_naming_the_preference(scene, monkeypatch):
    bpy, _, prefs = scene
    from blender_addon import preview

    prefs.symdrive_command = "/nonexistent/symdrive"
    for mode in ("COMMAND", "AUTO"):
        prefs.preview_backend = mode
        if mode == "AUTO":
            monkeypatch.setattr(preview, "in_process_available", lambda: False)
        with pytest.raises(RuntimeError, match="symdrive command '/nonexistent/symdrive' was not found; "
                                               "set Edit > Preferences > Add-ons > SymDrive > symdrive command"):
            bpy.ops.symdrive.render_preview(resolution=LINES)
    assert "SymDrive Preview" not in bpy.data.images
