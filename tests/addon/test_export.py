import json

import jsonschema
import numpy as np
import pytest

from blender_addon import actors
from symdrive_core import conventions
from symdrive_core.io.images import read_id_map, read_mask
from symdrive_core.io.mesh import read_mesh
from symdrive_core.io.ply import read_splats
from symdrive_core.scene import check_files, load_manifest
from symdrive_core.scene.manifest import SCHEMA_PATH
from tests.addon.scenes import HEIGHT, WIDTH, iou, rasterize_triangles, two_car_scene

pytestmark = pytest.mark.blender


@pytest.fixture
def exported(blender, tmp_path):
    objs = two_car_scene(blender, tmp_path / "assets")
    out = tmp_path / "package"
    assert blender.ops.symdrive.export_scene(directory=str(out)) == {"FINISHED"}
    return blender, objs, out


def test_two_vehicles_ten_frames_validate_in_the_core(exported):
    blender, objs, out = exported
    m = load_manifest(out, allow_external=True)  # assets not copied: the user's own files, outside
    check_files(m)
    jsonschema.validate(json.loads((out / "manifest.json").read_text()), json.loads(SCHEMA_PATH.read_text()))
    assert len(m.frames) == 10 and [f.timestamp for f in m.frames] == pytest.approx(np.arange(10) * 0.1)
    assert [a.id for a in m.actors] == ["car_a", "car_b"] and {a.kind for a in m.actors} == {"inserted"}
    assert m.effects.harmonize and m.background_splats is not None
    assert len(m.masks) == 20 and len(m.id_maps) == 10
    cam = m.cameras[0]
    assert (cam.name, cam.width, cam.height) == ("front", WIDTH, HEIGHT)
    # poses are relative to the background object, flip included, evaluated per frame
    scene = blender.context.scene
    bg_inv = np.linalg.inv(np.array(objs["background"].matrix_world))
    for i in (0, 4, 9):
        scene.frame_set(1 + i)
        for root, actor in zip(objs["cars"], m.actors, strict=True):
            np.testing.assert_allclose(
                actor.poses[i].matrix(), bg_inv @ np.array(actors.asset_world_matrix(root)), atol=1e-5
            )
        c2w = conventions.blender_camera_to_opencv(bg_inv @ np.array(objs["camera"].matrix_world))
        np.testing.assert_allclose(cam.frames[i].camera_to_world, c2w, atol=1e-5)
    # K: lens shift moves the principal point off centre (shift_x > 0 -> cx < W/2, shift_y < 0 -> cy < H/2)
    K = cam.frames[0].K
    assert K[0, 2] < WIDTH / 2 and K[1, 2] < HEIGHT / 2
    assert K[0, 0] == pytest.approx(30.0 * WIDTH / 36.0)


def test_masks_match_the_core_projection_of_each_actor(exported):
    """The boundary check: the core projects each actor's mesh and splats with the exported
    camera and pose; Blender's amodal mask must agree on every frame."""
    _, _, out = exported
    m = load_manifest(out, allow_external=True)
    cam = m.cameras[0]
    masks = {(e.frame, e.actor): e for e in m.masks}
    ious = {}
    for actor in m.actors:
        mesh = read_mesh(m.resolve(actor.mesh))  # the GLB the export writes, in the actor's frame
        verts, tris = mesh.verts, mesh.tris
        means = read_splats(m.resolve(actor.splats)).means
        for i, pose in enumerate(actor.poses):
            cf = cam.frames[i]
            uv, z = conventions.project_points(pose.apply(verts), cf.world_to_camera, cf.K)
            assert np.all(z > 0.1)
            silhouette = rasterize_triangles(uv[tris], cam.width, cam.height)
            amodal = read_mask(m.resolve(masks[i, actor.id].amodal)) > 0.5
            ious[actor.id, i] = iou(silhouette, amodal)
            # splat centres land on the mask too (checks the splat asset's frame, flip included)
            uv_g, _ = conventions.project_points(pose.apply(means), cf.world_to_camera, cf.K)
            px = np.floor(uv_g).astype(int)
            inside = (px[:, 0] >= 0) & (px[:, 0] < cam.width) & (px[:, 1] >= 0) & (px[:, 1] < cam.height)
            grown = amodal.copy()
            grown[1:] |= amodal[:-1]
            grown[:-1] |= amodal[1:]
            grown[:, 1:] |= grown[:, :-1].copy()
            grown[:, :-1] |= grown[:, 1:].copy()
            assert grown[px[inside, 1], px[inside, 0]].mean() > 0.99
    print("amodal mask IoU per (actor, frame):", {f"{a}/{i}": round(v, 4) for (a, i), v in ious.items()})
    assert min(ious.values()) >= 0.95


def test_visible_masks_are_amodal_minus_occluders(exported):
    _, _, out = exported
    m = load_manifest(out, allow_external=True)
    by_frame = {}
    for e in m.masks:
        amodal, visible = read_mask(m.resolve(e.amodal)) > 0.5, read_mask(m.resolve(e.visible)) > 0.5
        assert not np.any(visible & ~amodal)
        by_frame.setdefault(e.frame, {})[e.actor] = (amodal, visible)
    occluded = 0
    for idm in m.id_maps:
        ids = read_id_map(m.resolve(idm.path))
        for iid, actor_id in idm.ids.items():
            amodal, visible = by_frame[idm.frame][actor_id]
            np.testing.assert_array_equal(ids == iid, visible)
            occluded += int((amodal & ~visible).sum())
    assert occluded > 0  # car B crosses in front of car A


def test_reexport_replaces_the_package_and_refuses_other_folders(exported, tmp_path):
    blender, _, out = exported
    (out / "stale.txt").write_text("from an older export")
    assert blender.ops.symdrive.export_scene(
        directory=str(out), frame_start=3, frame_end=5, write_masks=False
    ) == {"FINISHED"}
    assert not (out / "stale.txt").exists() and not (out / "masks").exists()
    m = load_manifest(out, allow_external=True)
    assert len(m.frames) == 3 and m.masks == []
    other = tmp_path / "home"
    other.mkdir()
    (other / "precious.txt").write_text("keep me")
    with pytest.raises(RuntimeError, match="not a scene package"):
        blender.ops.symdrive.export_scene(directory=str(other))
    assert (other / "precious.txt").read_text() == "keep me"
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporary left behind


def test_export_errors_name_the_object(blender, tmp_path):
    with pytest.raises(RuntimeError, match="no camera to export"):
        blender.ops.symdrive.export_scene(directory=str(tmp_path / "a"))
    objs = two_car_scene(blender, tmp_path / "assets", n_frames=2)
    objs["background"].scale = (2.0, 2.0, 2.0)
    with pytest.raises(RuntimeError, match="background object is scaled"):
        blender.ops.symdrive.export_scene(directory=str(tmp_path / "b"))
    objs["background"].scale = (1.0, 1.0, 1.0)
    objs["cars"][0].scale = (1.0, 1.2, 1.0)
    with pytest.raises(RuntimeError, match="car_a: scale"):
        blender.ops.symdrive.export_scene(directory=str(tmp_path / "c"))
    assert not (tmp_path / "c").exists()


def test_absent_actor_has_null_pose_and_no_masks(blender, tmp_path):
    objs = two_car_scene(blender, tmp_path / "assets", n_frames=4)
    car_b = objs["cars"][1]
    from blender_addon import keyframes

    keyframes.key_presence(car_b, [1, 2, 3, 4], [True, True, False, False])
    out = tmp_path / "pkg"
    blender.ops.symdrive.export_scene(directory=str(out))
    m = load_manifest(out, allow_external=True)
    assert [p is None for p in m.actor("car_b").poses] == [False, False, True, True]
    assert sorted((e.frame, e.actor) for e in m.masks if e.actor == "car_b") == [(0, "car_b"), (1, "car_b")]
    assert all(m.id_maps[i].ids == {1: "car_a"} for i in (2, 3))


def test_the_core_runs_the_exported_package_end_to_end(exported, tmp_path):
    """The add-on's export is a package `symdrive run` takes as it is: planned from its effects,
    rendered and harmonized, with a report."""
    pytest.importorskip("torch")  # the backend; the add-on-only environments (make test-addon-5.2) lack it
    from symdrive_core.cli import main

    _, _, package = exported
    out = tmp_path / "run"
    # Assets not copied into the package: a run refuses them unless told they are the user's own.
    assert main(["run", str(package), "--out", str(out), "--quiet"]) == 2
    assert not (out / "render").exists()
    assert main(["run", str(package), "--out", str(out), "--quiet", "--allow-external-assets"]) == 0
    report = json.loads((out / "report.json").read_text())
    ran = {s["name"]: s["ran"] for s in report["stages"]}
    assert ran["render"] and ran["harmonize"]
    assert not ran["reconstruct"] and not ran["restore"] and not ran["finetune"]  # as the export's effects say
    assert len(list((out / "render").rglob("*.png"))) == 10
    assert len(list((out / "harmonize").rglob("*.region.png"))) > 0


def test_sun_lamp_exports_its_direction_and_the_shadow_ratio(blender, tmp_path):
    import math

    objs = two_car_scene(blender, tmp_path / "assets")
    assert blender.ops.symdrive.export_scene(directory=str(tmp_path / "overcast")) == {"FINISHED"}
    eff = load_manifest(tmp_path / "overcast").effects
    assert not eff.shadows and eff.sun_direction is None and eff.shadow_ratio is None
    sun = blender.data.objects.new("sun", blender.data.lights.new("sun", "SUN"))
    blender.context.scene.collection.objects.link(sun)
    sun.rotation_euler = (math.radians(40.0), 0.0, 0.0)  # light travels along R_x(40 deg) (0, 0, -1)
    blender.context.scene.symdrive.shadow_ratio = 0.3
    assert blender.ops.symdrive.export_scene(directory=str(tmp_path / "sunny")) == {"FINISHED"}
    eff = load_manifest(tmp_path / "sunny").effects
    travel = np.array([0.0, math.sin(math.radians(40.0)), -math.cos(math.radians(40.0))])
    expected = np.linalg.inv(np.array(objs["background"].matrix_world))[:3, :3] @ travel
    assert eff.shadows and eff.shadow_ratio == pytest.approx(0.3)
    np.testing.assert_allclose(eff.sun_direction, expected / np.linalg.norm(expected), atol=1e-6)
