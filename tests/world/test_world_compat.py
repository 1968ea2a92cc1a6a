"""The generator's Blender-version helpers, on whichever Blender this process has (4.2 .. 5.2)."""

import sys
from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
pytestmark = pytest.mark.blender

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "scripts"))

from world import compat, render  # noqa: E402


@pytest.fixture
def scene():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    return bpy.context.scene


def test_multilayer_exr_settings(scene):
    settings = scene.render.image_settings
    compat.set_multilayer_exr(settings)
    assert settings.file_format in ("OPEN_EXR_MULTILAYER", "OPEN_EXR")
    if hasattr(settings, "media_type"):
        assert settings.media_type == "MULTI_LAYER_IMAGE"
    else:
        assert settings.file_format == "OPEN_EXR_MULTILAYER"
    assert settings.color_depth == "32"


def test_node_trees_of_new_material_and_world(scene):
    mat = bpy.data.materials.new("m")
    assert "Principled BSDF" in compat.node_tree(mat).nodes
    world = bpy.data.worlds.new("w")
    assert "Background" in compat.node_tree(world).nodes


def test_single_scattering_sky(scene):
    world = bpy.data.worlds.new("w")
    sky = compat.node_tree(world).nodes.new("ShaderNodeTexSky")
    compat.set_single_scattering_sky(sky, dust_density=1.5)
    assert sky.sky_type in ("NISHITA", "SINGLE_SCATTERING")
    density = sky.dust_density if hasattr(sky, "dust_density") else sky.aerosol_density
    assert density == pytest.approx(1.5)


@pytest.mark.slow
def test_render_reads_colour_depth_and_index(scene):
    """A 16x8 Cycles render of a cube in front of the sky: every pass comes back."""
    render.setup_cycles(16, 8, samples=1, threads=1)
    bpy.ops.mesh.primitive_cube_add(size=2.0)
    bpy.context.active_object.pass_index = 7
    cam = render.make_camera()
    c2w = np.eye(4)
    c2w[:3, :3] = [[1, 0, 0], [0, 0, 1], [0, -1, 0]]  # OpenCV camera (x right, y down) looking along +y
    c2w[:3, 3] = [0, -6, 0]
    out = render.render(cam, c2w)
    assert out["rgb"].shape == (8, 16, 3) and out["depth"].shape == out["index"].shape == (8, 16)
    assert out["index"][4, 8] == 7 and out["depth"][4, 8] == pytest.approx(5.0, abs=1e-3)
    assert out["index"][0, 0] == 0 and out["depth"][0, 0] == 0.0  # sky
