"""Recorded vehicles: a package's existing actors imported, edited (removed, moved, retimed) and
exported as edits of the drive's track."""

import json

import numpy as np
import pytest

from blender_addon import recorded
from symdrive_core.io.ply import write_splats
from symdrive_core.rotations import quat_from_yaw
from symdrive_core.scene import Pose, check_files, load_manifest
from tests.addon.assets import car_mesh, surface_splats, write_obj
from tests.conftest import manifest_dict, random_gaussians

N = 6
CAR, VAN = "car_rec", "van_rec"


def _pose(x, y, z, yaw):
    return {"translation": [x, y, z], "rotation": [float(v) for v in quat_from_yaw(yaw)]}


def write_package(root):
    """Two recorded vehicles: a car reconstructed (splat PLY), a van not yet (its wlh only) that
    leaves the drive before the last frame."""
    d = manifest_dict(n_frames=N, width=64, height=48)
    d["actors"] = [
        {"id": CAR, "kind": "existing", "instance_id": 4, "assets": {"splats": "actors/car_rec.ply"},
         "wlh": [1.8, 4.0, 1.5], "poses": [_pose(8.0 + 0.5 * i, -1.5, 0.75, 0.05 * i) for i in range(N)]},
        {"id": VAN, "kind": "existing", "instance_id": 7, "assets": {}, "wlh": [2.0, 5.0, 2.0],
         "poses": [_pose(10.0 + i, 2.5, 1.0, -0.1) for i in range(N - 1)] + [None]},
    ]
    root.mkdir(parents=True)
    write_splats(root / "background.ply", random_gaussians(200, 0, 1, (10, 0, 1), 3.0))
    (root / "actors").mkdir()
    write_splats(root / "actors" / "car_rec.ply", surface_splats(*car_mesh(), 400, seed=3))
    (root / "manifest.json").write_text(json.dumps(d))
    return root


def import_package(blender, package):
    ops = blender.ops.symdrive
    assert ops.import_camera_rig(filepath=str(package / "manifest.json")) == {"FINISHED"}
    assert ops.import_splats(filepath=str(package / "background.ply")) == {"FINISHED"}
    assert ops.import_recorded_vehicles(filepath=str(package / "manifest.json")) == {"FINISHED"}
    return {ob.symdrive.actor_id: ob for ob in blender.context.scene.objects if ob.symdrive.role == "ACTOR"}


def export(blender, out, **kw):
    assert blender.ops.symdrive.export_scene(directory=str(out), **kw) == {"FINISHED"}
    m = load_manifest(out, allow_external=True)
    check_files(m)
    return m


def assert_same(poses, expected):
    assert [p is None for p in poses] == [e is None for e in expected]
    for p, e in zip(poses, expected):
        if p is not None:
            np.testing.assert_allclose(p.translation, e.translation, atol=1e-6)
            np.testing.assert_allclose(p.rotation * np.sign(p.rotation @ e.rotation), e.rotation, atol=1e-6)


@pytest.fixture
def imported(blender, tmp_path):
    package = write_package(tmp_path / "drive")
    return blender, package, load_manifest(package), import_package(blender, package)


@pytest.mark.blender
def test_recorded_vehicles_import_keyed_and_export_unchanged(imported, tmp_path):
    blender, package, source, roots = imported
    car, van = roots[CAR], roots[VAN]
    assert (car.symdrive.kind, car.symdrive.instance_id, van.symdrive.instance_id) == ("existing", 4, 7)
    assert car.children[0].symdrive.ply_path == str((package / "actors" / "car_rec.ply").resolve())
    assert [ob.display_type for ob in van.children] == ["WIRE"]  # the box of a vehicle not reconstructed yet
    scene = blender.context.scene
    scene.frame_set(N)
    assert van.hide_render and not car.hide_render  # the van left the drive before the last frame
    m = export(blender, tmp_path / "out")
    for actor in source.actors:
        got = m.actor(actor.id)
        assert (got.kind, got.instance_id, got.recorded_poses) == ("existing", actor.instance_id, None)
        assert_same(got.poses, actor.poses)
        np.testing.assert_allclose(got.wlh, actor.wlh, atol=1e-6)
    assert m.resolve(m.actor(CAR).splats).resolve() == (package / "actors" / "car_rec.ply").resolve()  # as inserted assets
    assert m.actor(VAN).splats is None and m.actor(VAN).mesh is None
    assert {e.actor for e in m.masks if e.frame == N - 1} == {CAR}


@pytest.mark.blender
def test_removed_moved_and_retimed_export_as_edits(imported, tmp_path):
    blender, _, source, roots = imported
    scene = blender.context.scene
    car, van = roots[CAR], roots[VAN]
    for ob in scene.objects:
        ob.select_set(ob is car)
    assert blender.ops.symdrive.remove_vehicle() == {"FINISHED"}
    scene.frame_set(3)  # package frame 2: moved 3 m along x there
    van.location.x += 3.0
    van.keyframe_insert("location", frame=3)
    for ob in scene.objects:
        ob.select_set(ob is van)
    assert blender.ops.symdrive.shift_vehicle_keys(frames=2) == {"FINISHED"}
    m = export(blender, tmp_path / "edited", write_masks=False)

    removed = m.actor(CAR)
    assert removed.poses == [None] * N
    assert_same(removed.recorded_poses, source.actor(CAR).poses)
    assert removed.edited_frames() == list(range(N))
    assert m.resolve(removed.splats).resolve() == source.resolve(source.actor(CAR).splats)  # kept, for the backend

    r = source.actor(VAN).poses
    moved = Pose(r[2].translation + [3.0, 0.0, 0.0], r[2].rotation)
    # two frames later: before its first key it waits where it was first seen; frame 5 is frame 3's pose
    assert_same(m.actor(VAN).poses, [r[0], r[0], r[0], r[1], moved, r[3]])
    assert_same(m.actor(VAN).recorded_poses, r)
    assert m.actor(VAN).edited_frames() == [1, 2, 3, 4]

    # the edited package imports as edited, its recorded track kept through the next export
    for root in (car, van):
        for ob in (*root.children_recursive, root):
            blender.data.objects.remove(ob)
    # the export references the source package's splats (outside it): the artist allows that
    blender.ops.symdrive.import_recorded_vehicles(filepath=str(tmp_path / "edited" / "manifest.json"),
                                                  allow_external_assets=True)
    again = export(blender, tmp_path / "again", write_masks=False)
    for actor in m.actors:
        assert_same(again.actor(actor.id).poses, actor.poses)
        assert_same(again.actor(actor.id).recorded_poses, actor.recorded_poses)


@pytest.mark.blender
def test_a_refined_vehicle_keeps_its_tracked_boxes_through_export(blender, tmp_path):
    """A later refinement starts from the tracker's boxes: the export keeps them for its frames."""
    package = write_package(tmp_path / "drive")
    d = json.loads((package / "manifest.json").read_text())
    d["actors"][0]["tracked_poses"] = [_pose(8.2 + 0.5 * i, -1.3, 0.7, 0.04 * i) for i in range(N - 1)] + [None]
    (package / "manifest.json").write_text(json.dumps(d))
    tracked = load_manifest(package).actor(CAR).tracked_poses
    import_package(blender, package)
    start = blender.context.scene.frame_start
    m = export(blender, tmp_path / "out", write_masks=False, frame_start=start + 1, frame_end=start + N - 1)
    assert_same(m.actor(CAR).tracked_poses, tracked[1:])
    assert m.actor(CAR).recorded_poses is None  # unedited: its poses are the refined ones
    assert m.actor(VAN).tracked_poses is None


@pytest.mark.blender
def test_export_into_the_package_itself_keeps_its_asset_paths(imported):
    blender, package, source, _ = imported
    m = export(blender, package, write_masks=False)
    assert m.actor(CAR).splats == source.actor(CAR).splats == "actors/car_rec.ply"
    assert m.background_splats == "background.ply"
    check_files(load_manifest(package))  # self-contained as before: nothing outside it


@pytest.mark.blender
def test_reimport_is_refused_while_the_ids_are_taken(imported):
    blender, package, _, _ = imported
    with pytest.raises(RuntimeError, match="car_rec: id: an actor with this id is already in the scene"):
        blender.ops.symdrive.import_recorded_vehicles(filepath=str(package / "manifest.json"))


@pytest.mark.blender
def test_a_vehicle_that_cannot_be_read_leaves_nothing_behind(blender, tmp_path):
    package = write_package(tmp_path / "drive")
    d = json.loads((package / "manifest.json").read_text())
    d["actors"][1]["assets"] = {"mesh": "actors/van.obj"}  # the second vehicle's file is missing
    (package / "manifest.json").write_text(json.dumps(d))
    before = set(blender.data.objects)
    with pytest.raises(RuntimeError, match="van.obj: file not found"):
        blender.ops.symdrive.import_recorded_vehicles(filepath=str(package / "manifest.json"))
    assert set(blender.data.objects) == before


@pytest.mark.blender
def test_a_recorded_mesh_keeps_the_actor_frame_through_export_and_reimport(blender, tmp_path):
    from blender_addon import actors

    package = tmp_path / "drive"
    package.mkdir()
    d = manifest_dict(n_frames=2, background=None)
    d["actors"] = [{"id": "bus", "kind": "existing", "assets": {"mesh": "bus.obj"},
                    "poses": [_pose(9.0, 0.0, 0.75, 0.3)] * 2}]
    verts, tris = car_mesh()  # longer than wide, its cabin towards the rear (-X)
    write_obj(package / "bus.obj", verts, tris)
    (package / "manifest.json").write_text(json.dumps(d))
    ops = blender.ops.symdrive
    ops.import_camera_rig(filepath=str(package / "manifest.json"))
    bounds = []
    for source in (package, tmp_path / "out"):
        assert ops.import_recorded_vehicles(filepath=str(source / "manifest.json"),
                                            allow_external_assets=True) == {"FINISHED"}
        root = blender.data.objects["bus"]
        pts = actors.geometry_points(root)
        bounds.append((pts.min(axis=0), pts.max(axis=0), pts[pts[:, 2] > 0.5, 0].mean()))
        if source == package:
            m = export(blender, tmp_path / "out", write_masks=False)
            assert m.actor("bus").mesh == "assets/bus/mesh.glb"  # written as Blender shows it
        for ob in (*root.children_recursive, root):
            blender.data.objects.remove(ob)
    for lo, hi, cabin_x in bounds:  # the OBJ, then the GLB the export wrote: same place in the actor frame
        np.testing.assert_allclose(lo, verts.min(axis=0), atol=1e-5)
        np.testing.assert_allclose(hi, verts.max(axis=0), atol=1e-5)
        assert cabin_x < 0


@pytest.mark.blender
def test_shift_keys_moves_pose_and_presence_keys_of_the_parts(blender):
    from blender_addon import keyframes

    root = blender.data.objects.new("root", None)
    part = blender.data.objects.new("part", None)
    for ob in (root, part):
        blender.context.scene.collection.objects.link(ob)
    part.parent = root
    keyframes.key_world_poses(root, [1, 4], [np.eye(4), np.eye(4) + np.eye(4, k=3)])
    keyframes.key_presence(root, [1, 4], [True, False])
    keyframes.shift_keys(root, -3)
    from blender_addon import compat

    for ob in (root, part):
        for fc in compat.object_fcurves(ob):
            assert [k.co.x for k in fc.keyframe_points] == [-2.0, 1.0], (ob.name, fc.data_path)


def test_recorded_frames_snap_back_and_an_edit_keeps_the_track():
    track = [Pose(np.array([float(i), 0.0, 0.0]), np.array([1.0, 0.0, 0.0, 0.0])) for i in range(3)]
    text = recorded.encode(5, track)
    at = recorded.at_frames(text, [4, 5, 6, 7, 8])
    assert at[0] is None and at[4] is None and at[2].translation[0] == 1.0
    drifted = [Pose(p.translation + 2e-7, p.rotation) for p in track]
    kept, rec = recorded.against_recorded(drifted, track)
    assert rec is None and all(k is t for k, t in zip(kept, track))  # float32 drift is no edit
    kept, rec = recorded.against_recorded([drifted[0], None, drifted[2]], track)
    assert rec is track and kept[0] is track[0] and kept[1] is None


@pytest.mark.blender
def test_a_vehicles_shadow_layer_goes_with_it_through_export(blender, tmp_path):
    """A recorded car's learnt shadow is its own: the export carries the layer file with it."""
    from symdrive_core.scene import Pose
    from symdrive_core.shadows.layer import ShadowLayer

    package = write_package(tmp_path / "drive")
    layer = ShadowLayer.initial(np.array([1.8, 4.0, 1.5]), np.array([0.3, -0.5, -0.8]),
                                Pose(np.zeros(3), np.array([1.0, 0, 0, 0])))
    layer.save(package / "actors" / "car_rec.shadow.safetensors")
    d = json.loads((package / "manifest.json").read_text())
    d["actors"][0]["assets"]["shadow"] = "actors/car_rec.shadow.safetensors"
    (package / "manifest.json").write_text(json.dumps(d))
    import_package(blender, package)
    blender.context.scene.symdrive.copy_assets = True
    m = export(blender, tmp_path / "out", write_masks=False)
    assert m.actor(CAR).shadow is not None and m.actor(VAN).shadow is None
    back = ShadowLayer.load(m.resolve(m.actor(CAR).shadow))
    assert np.array_equal(back.occlusion, layer.occlusion) and np.allclose(back.origin, layer.origin)
