import numpy as np
import pytest

from symdrive_core.gaussians import SH_C0
from symdrive_core.io.ply import write_splats
from tests.compressed_ply_files import BOX, pack_11_10_11, write_compressed_ply
from tests.conftest import random_gaussians

pytestmark = pytest.mark.blender


def _attribute(mesh, name, prop, width):
    attr = mesh.attributes[name]
    out = np.empty(len(attr.data) * width, dtype=np.float32)
    attr.data.foreach_get(prop, out)
    return out.reshape(-1, width) if width > 1 else out


def _displayed_radii(blender, obj) -> np.ndarray:
    """Radii of the point cloud the display modifier makes of ``obj``: it comes out of the
    depsgraph as an instance (the one way to reach it on every Blender from 4.2)."""
    for inst in blender.context.evaluated_depsgraph_get().object_instances:
        if inst.is_instance and inst.object.type == "POINTCLOUD" and inst.parent.original == obj:
            cloud = inst.object.data
            radius = np.empty(len(cloud.points), np.float32)
            cloud.attributes["radius"].data.foreach_get("value", radius)
            return radius
    raise AssertionError(f"no displayed point cloud for {obj.name}")


@pytest.mark.parametrize("degree", [0, 3])
def test_import_keeps_positions_opacity_scale_and_dc_colour(blender, tmp_path, degree):
    g = random_gaussians(500, degree=degree, seed=degree)
    path = tmp_path / f"cloud_d{degree}.ply"
    write_splats(path, g)
    assert blender.ops.symdrive.import_splats(filepath=str(path)) == {"FINISHED"}
    obj = blender.context.active_object
    s = obj.symdrive
    assert (s.role, s.splat_count, s.display_count, s.sh_degree) == ("SPLATS", 500, 500, degree)
    assert s.ply_path == str(path.resolve()) and len(s.ply_sha256) == 64
    assert blender.context.scene.symdrive.background == obj
    mesh = obj.data
    co = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", co)
    np.testing.assert_allclose(co.reshape(-1, 3), g.means, atol=1e-6)
    np.testing.assert_allclose(_attribute(mesh, "opacity", "value", 1), g.opacities, atol=1e-6)
    np.testing.assert_allclose(_attribute(mesh, "scale", "vector", 3), g.scales, rtol=1e-5)
    rgb = np.clip(SH_C0 * g.sh[:, 0] + 0.5, 0, None)
    linear = np.where(rgb <= 0.04045, rgb / 12.92, ((rgb + 0.055) / 1.055) ** 2.4)
    np.testing.assert_allclose(_attribute(mesh, "color", "color", 4)[:, :3], linear, atol=1e-5)
    # the .blend keeps no SH payload: only the display attributes exist
    assert {a.name for a in mesh.attributes if not a.name.startswith(".")} == {
        "position",
        "opacity",
        "scale",
        "color",
    }
    # the display modifier: one point per splat that is not nearly transparent, radius = mean scale
    shown = g.opacities >= 0.05
    radius = _displayed_radii(blender, obj)
    assert len(radius) == shown.sum()
    np.testing.assert_allclose(radius, g.scales[shown].mean(axis=1), rtol=1e-5)


def test_subsampled_display_keeps_the_file_count(blender, tmp_path):
    path = tmp_path / "big.ply"
    write_splats(path, random_gaussians(1000))
    assert blender.ops.symdrive.import_splats(filepath=str(path), max_points=100) == {"FINISHED"}
    s = blender.context.active_object.symdrive
    assert (s.splat_count, s.display_count, len(blender.context.active_object.data.vertices)) == (
        1000,
        100,
        100,
    )


def test_compressed_ply_imports_as_splats(blender, tmp_path):
    path = tmp_path / "scene.compressed.ply"
    write_compressed_ply(path, [BOX, BOX], [(pack_11_10_11(2047, 0, 0), 0, 0, 0xFF0000FF)] * 300)
    assert blender.ops.symdrive.import_splats(filepath=str(path)) == {"FINISHED"}
    obj = blender.context.active_object
    assert (obj.symdrive.role, obj.symdrive.splat_count, obj.symdrive.sh_degree) == ("SPLATS", 300, 0)
    co = np.empty(len(obj.data.vertices) * 3, np.float32)
    obj.data.vertices.foreach_get("co", co)
    np.testing.assert_allclose(co.reshape(-1, 3), [[2.0, 0.0, 0.0]] * 300)


def test_non_3dgs_ply_is_reported_not_raised_as_a_traceback(blender, tmp_path):
    path = tmp_path / "points.ply"
    path.write_text(
        "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
        "property float z\nend_header\n0 0 0\n1 1 1\n"
    )
    with pytest.raises(RuntimeError, match="not a 3DGS splat file"):
        blender.ops.symdrive.import_splats(filepath=str(path))
    assert len(blender.data.objects) == 0 and len(blender.data.meshes) == 0


def test_truncated_ply_is_reported(blender, tmp_path):
    path = tmp_path / "cut.ply"
    write_splats(path, random_gaussians(200, degree=3))
    data = path.read_bytes()
    path.write_bytes(data[: len(data) - 1000])
    with pytest.raises(RuntimeError, match="truncated"):
        blender.ops.symdrive.import_splats(filepath=str(path))
    assert len(blender.data.objects) == 0


def test_missing_file_is_reported(blender, tmp_path):
    with pytest.raises(RuntimeError, match="file not found"):
        blender.ops.symdrive.import_splats(filepath=str(tmp_path / "nope.ply"))


def test_every_operator_supports_undo(blender):
    import blender_addon

    operators = [c for c in blender_addon._classes() if issubclass(c, blender.types.Operator)]
    assert len(operators) >= 8
    for op in operators:
        assert {"REGISTER", "UNDO"} <= set(op.bl_options), op.bl_idname
