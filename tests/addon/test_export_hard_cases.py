"""Exports of scenes an artist builds outside the happy path: another scene than the window's, names
that clean alike, a re-export that copies assets, a vehicle's own camera and light, mirrored
cameras, a moving background, a road drawn as a bevelled curve, an empty splat file, a vehicle
with both a mesh and splats, a duplicated vehicle."""

import numpy as np
import pytest

from blender_addon import export
from symdrive_core.io.mesh import read_mesh
from symdrive_core.io.ply import read_splats, write_splats
from tests.addon.assets import write_car
from tests.addon.scenes import add_camera, two_car_scene

pytestmark = pytest.mark.blender


def _export(scene, out, **kw):
    return export.export_scene(scene, export.ExportOptions(out=out, write_masks=kw.pop("masks", False), **kw))


def test_a_scene_other_than_the_windows_exports_its_own_motion(blender, tmp_path):
    """``headless --scene``: the scene named need not be the one a saved .blend opens on."""
    two_car_scene(blender, tmp_path / "assets", n_frames=3)
    blender.context.scene.name = "Street"
    blender.context.window.scene = blender.data.scenes.new("Other")
    blend = tmp_path / "two_scenes.blend"
    blender.ops.wm.save_as_mainfile(filepath=str(blend))
    blender.ops.wm.open_mainfile(filepath=str(blend))
    assert blender.context.scene.name == "Other"
    m = _export(blender.data.scenes["Street"], tmp_path / "pkg")
    xs = [f.camera_to_world[0, 3] for f in m.cameras[0].frames]
    np.testing.assert_allclose(np.diff(xs), np.diff(xs)[0], atol=1e-6)  # steady, as keyed
    assert abs(xs[2] - xs[0]) > 0.5  # the camera's 0.3 m a frame, not one frame three times
    a = m.actor("car_b")
    assert np.linalg.norm(a.poses[2].translation - a.poses[0].translation) > 1.0


def test_camera_names_that_clean_alike_get_their_own_mask_files(blender, tmp_path):
    objs = two_car_scene(blender, tmp_path / "assets", n_frames=1)
    objs["camera"].name = "Cam 1"
    other = add_camera(blender, "Cam_1")
    other.location = objs["camera"].location
    other.rotation_euler = (objs["camera"].rotation_euler[0], 0.0, 1.57)  # looking sideways
    m = _export(blender.context.scene, tmp_path / "pkg", masks=True)
    folders = {c: {e.amodal.rsplit("/", 1)[0] for e in m.masks if e.camera == c} for c in ("Cam 1", "Cam_1")}
    assert folders["Cam 1"].isdisjoint(folders["Cam_1"]) and all(folders.values())
    assert len({i.path for i in m.id_maps}) == len(m.id_maps) == 2


def test_a_reexport_copying_assets_keeps_each_cars_own_splats(blender, tmp_path):
    two_car_scene(blender, tmp_path / "assets", n_frames=1)
    out = tmp_path / "pkg"
    first = _export(blender.context.scene, out, copy_assets=True)
    before = {a.id: read_splats(first.resolve(a.splats)).means.copy() for a in first.actors}
    mesh, splats = write_car(tmp_path / "assets" / "car_c", "car_c", seed=5)
    blender.context.scene.cursor.location = (15.0, -2.0, 0.0)
    blender.ops.symdrive.import_vehicle(filepath=str(mesh), splat_filepath=str(splats))
    again = _export(blender.context.scene, out, copy_assets=True)
    paths = [a.splats for a in again.actors]
    assert len(set(paths)) == 3
    for a in again.actors:
        expected = before.get(a.id, read_splats(splats).means)
        np.testing.assert_array_equal(read_splats(again.resolve(a.splats)).means, expected)


def test_a_vehicles_own_camera_and_light_are_not_the_streets(blender, tmp_path):
    objs = two_car_scene(blender, tmp_path / "assets", n_frames=1)
    showcase = add_camera(blender, "Showcase")
    showcase.parent = objs["cars"][0]
    sun = blender.data.objects.new("StudioSun", blender.data.lights.new("StudioSun", "SUN"))
    blender.context.scene.collection.objects.link(sun)
    sun.parent = objs["cars"][0]
    m = _export(blender.context.scene, tmp_path / "pkg")
    assert [c.name for c in m.cameras] == ["front"] and m.effects.sun_direction is None


def test_a_mirrored_camera_and_a_moving_background_are_refused_naming_them(blender, tmp_path):
    objs = two_car_scene(blender, tmp_path / "assets", n_frames=2)
    objs["camera"].scale = (-1.0, 1.0, 1.0)
    with pytest.raises(Exception, match="front: scale: mirrored by a negative scale"):
        _export(blender.context.scene, tmp_path / "a")
    objs["camera"].scale = (1.0, 1.0, 1.0)
    bg = objs["background"]
    bg.keyframe_insert("location", frame=1)
    bg.location.x += 2.0
    bg.keyframe_insert("location", frame=2)
    with pytest.raises(Exception, match="background: matrix_world: the background object moves"):
        _export(blender.context.scene, tmp_path / "b")
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()


@pytest.mark.parametrize("surface", [{"bevel_depth": 0.5}, {"extrude": 1.0}])
def test_driving_along_a_curve_drawn_as_a_road_follows_its_centre_line(blender, tmp_path, surface):
    bpy = blender
    scene = bpy.context.scene
    scene.render.fps, scene.frame_start, scene.frame_end = 10, 1, 11
    mesh, splats = write_car(tmp_path / "car", "car", seed=1)
    bpy.ops.symdrive.import_vehicle(filepath=str(mesh), splat_filepath=str(splats))
    car = bpy.context.active_object
    data = bpy.data.curves.new("road", "CURVE")
    data.dimensions = "3D"
    spline = data.splines.new("POLY")
    spline.points.add(1)
    spline.points[0].co, spline.points[1].co = (0.0, 5.0, 0.0, 1.0), (20.0, 5.0, 0.0, 1.0)
    for k, v in surface.items():
        setattr(data, k, v)
    scene.collection.objects.link(bpy.data.objects.new("road", data))
    scene.frame_set(1)
    assert bpy.ops.symdrive.follow_curve(curve="road", speed=10.0) == {"FINISHED"}
    for f, x in ((1, 0.0), (6, 5.0), (11, 10.0)):
        scene.frame_set(f)
        np.testing.assert_allclose(car.matrix_world.translation[:2], (x, 5.0), atol=1e-4)
        assert abs(car.matrix_world.to_euler().z) < 1e-4
    assert {k: getattr(data, k) for k in surface} == surface  # the road keeps its look


def test_an_empty_splat_file_is_refused_at_import(blender, tmp_path):
    path = tmp_path / "empty.ply"
    write_splats(path, read_splats(write_car(tmp_path / "car", "car")[1]).subset(np.arange(0)))
    with pytest.raises(RuntimeError, match="no splats"):
        blender.ops.symdrive.import_splats(filepath=str(path))


def test_a_vehicle_with_mesh_and_splats_ships_its_mesh_in_its_own_frame(blender, tmp_path):
    two_car_scene(blender, tmp_path / "assets", n_frames=1)
    m = _export(blender.context.scene, tmp_path / "pkg", copy_assets=True)
    for a in m.actors:
        assert a.mesh == f"assets/{a.id}/mesh.glb"
        verts = read_mesh(m.resolve(a.mesh)).verts
        np.testing.assert_allclose(np.ptp(verts, axis=0), [a.wlh[1], a.wlh[0], a.wlh[2]], rtol=0.02)


def test_a_duplicated_vehicle_is_named_with_the_vehicle_it_copies(blender, tmp_path):
    objs = two_car_scene(blender, tmp_path / "assets", n_frames=1)
    objs["cars"][1].symdrive.instance_id = objs["cars"][0].symdrive.instance_id
    with pytest.raises(RuntimeError, match=r"car_b.*: instance_id: instance id 1 is 'car_a'.s too"):
        blender.ops.symdrive.export_scene(directory=str(tmp_path / "pkg"))


def test_a_vehicle_in_a_collection_disabled_in_renders_is_absent(blender, tmp_path):
    objs = two_car_scene(blender, tmp_path / "assets", n_frames=1)
    parked = blender.data.collections.new("Parked")
    inner = blender.data.collections.new("Inner")
    blender.context.scene.collection.children.link(parked)
    parked.children.link(inner)
    car = objs["cars"][0]
    for c in list(car.users_collection):
        c.objects.unlink(car)
    inner.objects.link(car)
    assert _export(blender.context.scene, tmp_path / "on").actor("car_a").poses[0] is not None
    parked.hide_render = True  # the parent's switch reaches the collection inside it
    assert _export(blender.context.scene, tmp_path / "off").actor("car_a").poses[0] is None
