import json
import os

import numpy as np
import pytest

from blender_addon import actors
from tests.addon.assets import WLH, write_car

pytestmark = pytest.mark.blender


def _world_points(blender, root):
    blender.context.view_layer.update()
    pts = actors.geometry_points(root)
    M = np.array(root.matrix_world)
    return pts @ M[:3, :3].T + M[:3, 3]


def test_mesh_and_splats_under_one_grounded_actor(blender, tmp_path):
    obj_path, ply_path = write_car(tmp_path, "car")
    blender.context.scene.cursor.location = (5.0, -2.0, 0.3)
    assert blender.ops.symdrive.import_vehicle(filepath=str(obj_path), splat_filepath=str(ply_path)) == {
        "FINISHED"
    }
    root = blender.context.active_object
    s = root.symdrive
    assert (s.role, s.kind, s.actor_id, s.instance_id) == ("ACTOR", "inserted", "car", 1)
    kinds = sorted(ob.symdrive.role for ob in root.children)
    assert kinds == ["MESH", "SPLATS"]
    for child in root.children:  # no flip asked: the parts sit in the actor frame unchanged
        np.testing.assert_allclose(np.array(child.matrix_basis), np.eye(4), atol=1e-7)
    np.testing.assert_allclose(s.wlh, WLH, atol=1e-5)
    assert s.ground_offset == pytest.approx(0.75, abs=1e-5)  # h/2 for a centred asset
    pts = _world_points(blender, root)
    assert pts[:, 2].min() == pytest.approx(0.3, abs=1e-5)  # underside on the cursor's ground
    np.testing.assert_allclose(root.location, (5.0, -2.0, 1.05), atol=1e-6)
    # the mesh keeps the asset frame: X forward, Z up (OBJ written Z-up)
    np.testing.assert_allclose(np.ptp(pts, axis=0), [WLH[1], WLH[0], WLH[2]], atol=1e-5)


def test_second_import_gets_new_ids_and_wlh_json_wins(blender, tmp_path):
    obj_path, _ = write_car(tmp_path, "car")
    (tmp_path / "wlh.json").write_text(json.dumps({"w": 1.9, "l": 4.2, "h": 1.6}))
    blender.ops.symdrive.import_vehicle(filepath=str(obj_path))
    blender.ops.symdrive.import_vehicle(filepath=str(obj_path))
    roots = actors.all_actors(blender.context.scene)
    assert [r.symdrive.actor_id for r in roots] == ["car", "car_2"]
    assert [r.symdrive.instance_id for r in roots] == [1, 2]
    np.testing.assert_allclose(roots[1].symdrive.wlh, (1.9, 4.2, 1.6), atol=1e-6)
    roots[0].name = "renamed"  # the actor id is stable under renames
    assert roots[0].symdrive.actor_id == "car"


def test_forward_flip_turns_the_asset_and_the_exported_frame(blender, tmp_path):
    _, ply_path = write_car(tmp_path, "car")
    blender.ops.symdrive.import_vehicle(filepath=str(ply_path), flip_forward=True)
    root = blender.context.active_object
    blender.context.view_layer.update()
    local = actors.geometry_points(root)
    # the cabin sits at the asset's rear (-X); flipped, it sits at the actor's +X side
    top = local[local[:, 2] > 0.3]  # the cabin (root frame = asset frame turned)
    assert top[:, 0].mean() > 0
    A = np.array(actors.asset_world_matrix(root))
    np.testing.assert_allclose(A[:3, 0], [-1, 0, 0], atol=1e-6)
    root.symdrive.flip_forward = False
    root.symdrive.flip_forward = False  # setting the same value again changes nothing
    blender.context.view_layer.update()
    assert actors.geometry_points(root)[:, 0].mean() == pytest.approx(-local[:, 0].mean(), abs=1e-5)


def test_broken_mesh_is_reported_and_leaves_nothing_behind(blender, tmp_path):
    bad = tmp_path / "broken.glb"
    bad.write_bytes(b"not a gltf file at all")
    with pytest.raises(RuntimeError, match="broken.glb: Blender's importer failed"):
        blender.ops.symdrive.import_vehicle(filepath=str(bad))
    assert not [ob for ob in blender.data.objects if ob.symdrive.role == "ACTOR"]
    with pytest.raises(RuntimeError, match="unsupported mesh format"):
        blender.ops.symdrive.import_vehicle(filepath=str(tmp_path / "car.fbx"))


def test_special_and_oversized_files_are_reported_not_raised(blender, tmp_path):
    """A FIFO, a device, and an OBJ whose only face-bearing line is too long for Blender's
    importer: each is one operator error naming the file, and nothing is left behind."""
    fifo = tmp_path / "pipe.obj"
    os.mkfifo(fifo)
    huge = tmp_path / "huge.obj"
    huge.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 " + "3" * 300_000 + "\n")
    for path, message in ((fifo, "pipe.obj"), ("/dev/zero", "/dev/zero"), (huge, "huge.obj: f: the importer produced no faces")):
        with pytest.raises(RuntimeError, match=message):
            blender.ops.symdrive.import_vehicle(filepath=str(path))
    assert not [ob for ob in blender.data.objects if ob.symdrive.role == "ACTOR"]
    assert not [ob for ob in blender.data.objects if ob.type == "MESH"]
