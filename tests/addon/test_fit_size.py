"""Downloaded cars at the wrong size or on their side: import axes, the size check, Fit to Size.

The "downloaded" cars are written in the test the way public models come: a GLB written by
Blender's own glTF exporter (glTF is +Y up, the model's front along +Z) in centimetres with its
origin on the ground, and a Y-up OBJ whose front is -Z.
"""

import json
import math

import numpy as np
import pytest

from blender_addon import actors, compat, mesh_import
from tests.addon.assets import WLH, car_mesh, write_car, write_obj

pytestmark = pytest.mark.blender


def _cabin_is_at_the_rear(root) -> bool:
    pts = actors.geometry_points(root)
    top = pts[pts[:, 2] > pts[:, 2].min() + 0.8 * np.ptp(pts[:, 2])]
    return top[:, 0].mean() < pts[:, 0].mean()


def write_glb_car(bpy, path, scale=100.0):
    """The test car as a glTF file would hold it: front along glTF +Z, +Y up, ``scale`` units per
    metre, origin under the car."""
    verts, tris = car_mesh()
    v = verts.copy()
    v[:, 2] -= verts[:, 2].min()  # origin on the ground
    # Blender frame for the exporter: front along -Y (the exporter maps Blender -Y to glTF +Z)
    v = np.stack([v[:, 1], -v[:, 0], v[:, 2]], axis=1) * scale
    me = bpy.data.meshes.new("downloaded")
    me.from_pydata(v.tolist(), [], tris.tolist())
    ob = bpy.data.objects.new("downloaded", me)
    bpy.context.scene.collection.objects.link(ob)
    for other in bpy.context.scene.objects:
        other.select_set(other == ob)
    bpy.context.view_layer.objects.active = ob
    import addon_utils

    addon_utils.enable("io_scene_gltf2", default_set=False)
    bpy.ops.export_scene.gltf(filepath=str(path), export_format="GLB", use_selection=True)
    bpy.data.objects.remove(ob, do_unlink=True)
    bpy.data.meshes.remove(me)
    return path


def test_axis_matrix_maps_the_named_file_axes_to_the_actor_frame():
    np.testing.assert_allclose(mesh_import.axis_matrix("Z", "X"), np.eye(3))
    R = mesh_import.axis_matrix("Y", "NEGATIVE_Z")  # a typical Y-up OBJ facing -Z
    np.testing.assert_allclose(R @ [0, 0, -1], [1, 0, 0])
    np.testing.assert_allclose(R @ [0, 1, 0], [0, 0, 1])
    assert np.linalg.det(R) == pytest.approx(1.0)
    with pytest.raises(ValueError, match="perpendicular"):
        mesh_import.axis_matrix("Z", "NEGATIVE_Z")


def test_size_check_flags_wrong_units_and_cars_on_end():
    assert actors.size_problem((1.8, 4.5, 1.5)) is None
    assert "long" in actors.size_problem((180, 450, 150))
    assert "long" in actors.size_problem((1.8, 1.5, 4.5))  # standing on its nose: 1.5 m long
    assert "up axis" in actors.size_problem((1.8, 3.0, 3.5))


def test_glb_car_in_centimetres_imports_facing_forward_and_fits_to_length(blender, tmp_path):
    glb = write_glb_car(blender, tmp_path / "truck.glb")
    scene = blender.context.scene
    scene.cursor.location = (4.0, 2.0, 0.25)
    assert blender.ops.symdrive.import_vehicle(filepath=str(glb)) == {"FINISHED"}
    root = blender.context.active_object
    np.testing.assert_allclose(root.symdrive.wlh, np.array(WLH) * 100, rtol=1e-4)
    assert actors.size_problem(root.symdrive.wlh) is not None  # the operator reported it
    assert _cabin_is_at_the_rear(root)  # glTF +Z front became the actor's +X
    pts = actors.geometry_points(root)
    np.testing.assert_allclose(0.5 * (pts.min(axis=0) + pts.max(axis=0)), 0, atol=1e-3)  # box-centred

    assert blender.ops.symdrive.fit_vehicle_size(length=4.0) == {"FINISHED"}
    np.testing.assert_allclose(root.symdrive.wlh, WLH, rtol=1e-4)
    assert actors.size_problem(root.symdrive.wlh) is None
    np.testing.assert_allclose(root.scale, (1, 1, 1))  # the empty is never scaled
    assert all(np.allclose(ob.scale, 1) or ob.type != "MESH" for ob in root.children_recursive)
    blender.context.view_layer.update()
    world = actors.geometry_points(root) @ np.array(root.matrix_world)[:3, :3].T + np.array(root.location)
    assert world[:, 2].min() == pytest.approx(0.25, abs=1e-4)  # still standing on the cursor's ground
    np.testing.assert_allclose(root.location[:2], (4.0, 2.0), atol=1e-6)
    assert root.symdrive.ground_offset == pytest.approx(WLH[2] / 2, abs=1e-4)


def test_y_up_obj_with_the_axes_named_at_import(blender, tmp_path):
    verts, tris = car_mesh()
    yup = np.stack([-verts[:, 1], verts[:, 2], -verts[:, 0]], axis=1)  # front -Z, up +Y
    path = write_obj(tmp_path / "car.obj", yup, tris)
    blender.ops.symdrive.import_vehicle(filepath=str(path))  # taken as Z-up: on its side
    assert actors.size_problem(blender.context.active_object.symdrive.wlh) is not None
    assert blender.ops.symdrive.import_vehicle(
        filepath=str(path), up_axis="Y", forward_axis="NEGATIVE_Z"
    ) == {"FINISHED"}
    root = blender.context.active_object
    np.testing.assert_allclose(root.symdrive.wlh, WLH, atol=1e-5)
    assert _cabin_is_at_the_rear(root)
    with pytest.raises(RuntimeError, match="perpendicular"):
        blender.ops.symdrive.import_vehicle(filepath=str(path), up_axis="Z", forward_axis="NEGATIVE_Z")


def test_fit_reads_wlh_json_and_moves_the_keys_of_an_animated_actor(blender, tmp_path):
    verts, tris = car_mesh()
    path = write_obj(tmp_path / "car.obj", verts * 0.5, tris)  # half size: 2 m long
    scene = blender.context.scene
    blender.ops.symdrive.import_vehicle(filepath=str(path))
    root = blender.context.active_object
    for f, x in ((1, 0.0), (11, 10.0)):
        scene.frame_set(f)
        root.location.x = x
        blender.ops.symdrive.key_pose()
    (tmp_path / "wlh.json").write_text(json.dumps({"w": 1.9, "l": 4.6, "h": 1.4}))
    assert blender.ops.symdrive.fit_vehicle_size() == {"FINISHED"}
    np.testing.assert_allclose(root.symdrive.wlh, (1.9, 4.6, 1.4), atol=1e-5)
    keyed_z = [k.co[1] for fc in compat.object_fcurves(root) if fc.data_path == "location"
               and fc.array_index == 2 for k in fc.keyframe_points]
    assert keyed_z and np.allclose(keyed_z, 0.7, atol=1e-5)  # the new h / 2 above the ground
    for f in (1, 6, 11):
        scene.frame_set(f)
        assert root.location.z == pytest.approx(0.7, abs=1e-5)
    with pytest.raises(RuntimeError, match="w, l and h"):
        blender.ops.symdrive.fit_vehicle_size(w=2.0)


def test_fit_refuses_actors_whose_size_is_their_splat_file(blender, tmp_path):
    obj, ply = write_car(tmp_path, "car")
    blender.ops.symdrive.import_vehicle(filepath=str(obj), splat_filepath=str(ply))
    with pytest.raises(RuntimeError, match="splat cloud"):
        blender.ops.symdrive.fit_vehicle_size(length=5.0)
    np.testing.assert_allclose(blender.context.active_object.symdrive.wlh, WLH, atol=1e-5)


def test_rotated_parts_scale_in_the_actor_frame(blender, tmp_path):
    verts, tris = car_mesh()
    path = write_obj(tmp_path / "car.obj", verts, tris)
    blender.ops.symdrive.import_vehicle(filepath=str(path))
    root = blender.context.active_object
    part = root.children[0]
    part.rotation_euler.z = math.pi / 2  # a part turned inside the actor: now 1.8 long, 4 wide
    blender.context.view_layer.update()
    assert blender.ops.symdrive.fit_vehicle_size(w=2.0, l=3.0, h=1.0) == {"FINISHED"}
    np.testing.assert_allclose(root.symdrive.wlh, (2.0, 3.0, 1.0), atol=1e-5)


def test_mesh_only_actor_is_exported_as_a_glb_in_its_own_frame(blender, tmp_path):
    from symdrive_core.scene import check_files, load_manifest
    from tests.addon.scenes import add_camera

    (tmp_path / "downloads").mkdir()
    glb = write_glb_car(blender, tmp_path / "downloads" / "truck.glb")
    scene = blender.context.scene
    scene.frame_start, scene.frame_end = 1, 2
    scene.render.resolution_x, scene.render.resolution_y = 32, 24
    scene.cursor.location = (10.0, 1.0, 0.0)
    blender.ops.symdrive.import_vehicle(filepath=str(glb), flip_forward=True)
    root = blender.context.active_object
    blender.ops.symdrive.fit_vehicle_size(length=4.0)
    root.rotation_euler.z = 0.7
    scene.camera = add_camera(blender)
    before = set(blender.data.objects)
    out = tmp_path / "package"
    assert blender.ops.symdrive.export_scene(directory=str(out)) == {"FINISHED"}
    assert set(blender.data.objects) == before  # the stand-ins are gone
    m = load_manifest(out)
    check_files(m)
    actor = m.actors[0]
    assert actor.splats is None and actor.mesh == "assets/truck/mesh.glb"
    # Read back as the backend reads it (glTF's +Y up turned to Z up): the car's own frame.
    from symdrive_core.io.mesh import read_mesh

    verts = read_mesh(m.resolve(actor.mesh)).verts
    lo, hi = verts.min(axis=0), verts.max(axis=0)
    half = np.array([WLH[1], WLH[0], WLH[2]]) / 2  # X forward, Y left, Z up, centred
    np.testing.assert_allclose(lo, -half, atol=1e-4)
    np.testing.assert_allclose(hi, half, atol=1e-4)
