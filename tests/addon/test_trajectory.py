import math

import numpy as np
import pytest

from blender_addon import compat
from tests.addon.assets import write_car

pytestmark = pytest.mark.blender


def _vehicle(blender, tmp_path, name="car", **kw):
    _, ply = write_car(tmp_path / name, name)
    assert blender.ops.symdrive.import_vehicle(filepath=str(ply), **kw) == {"FINISHED"}
    return blender.context.active_object


def _track(blender, root, frames):
    scene = blender.context.scene
    pos, fwd = [], []
    for f in frames:
        scene.frame_set(f)
        M = np.array(root.matrix_world)
        pos.append(M[:3, 3].copy())
        fwd.append(M[:3, 0].copy())
    return np.array(pos), np.array(fwd)


def _curve(blender, points, cyclic=False, kind="POLY"):
    data = blender.data.curves.new("path", "CURVE")
    data.dimensions = "3D"
    spline = data.splines.new(kind)
    spline.points.add(len(points) - 1)
    for p, co in zip(spline.points, points, strict=True):
        p.co = (*co, 1.0)
    spline.use_cyclic_u = cyclic
    ob = blender.data.objects.new("path", data)
    blender.context.scene.collection.objects.link(ob)
    return ob


def test_straight_curve_gives_exact_speed_and_heading(blender, tmp_path):
    scene = blender.context.scene
    scene.render.fps, scene.frame_start, scene.frame_end = 10, 1, 20
    root = _vehicle(blender, tmp_path)
    curve = _curve(blender, [(0, 0, 0), (0, 50, 0)])
    curve.location = (3, 1, 0.5)
    scene.frame_set(1)
    assert blender.ops.symdrive.follow_curve(curve="path", speed=7.0) == {"FINISHED"}
    pos, fwd = _track(blender, root, range(1, 21))
    f = np.arange(20)
    np.testing.assert_allclose(pos[:, 1], 1 + 0.7 * f, atol=1e-5)
    np.testing.assert_allclose(pos[:, 0], 3, atol=1e-5)
    np.testing.assert_allclose(pos[:, 2], 0.5 + root.symdrive.ground_offset, atol=1e-5)
    np.testing.assert_allclose(fwd, np.tile([0, 1, 0], (20, 1)), atol=1e-6)


def test_circle_heading_follows_the_tangent_at_the_set_speed(blender, tmp_path):
    scene = blender.context.scene
    scene.render.fps, scene.frame_start, scene.frame_end = 24, 1, 96
    root = _vehicle(blender, tmp_path)
    blender.ops.curve.primitive_bezier_circle_add(radius=10.0, location=(0, 0, 0))
    circle = blender.context.active_object
    circle.data.resolution_u = 32
    scene.symdrive.curve, scene.symdrive.speed = circle, 12.0
    blender.context.view_layer.objects.active = root
    scene.frame_set(1)
    assert blender.ops.symdrive.follow_curve() == {"FINISHED"}
    pos, fwd = _track(blender, root, range(1, 97))
    radius = np.linalg.norm(pos[:, :2], axis=1)
    np.testing.assert_allclose(radius, 10.0, atol=5e-3)  # a 4-point Bezier circle is off by <= 0.03 %
    step = np.linalg.norm(np.diff(pos[:, :2], axis=0), axis=1)
    chord = 2 * 10.0 * np.sin(12.0 / 24 / (2 * 10.0))  # arc of speed/fps metres
    np.testing.assert_allclose(step, chord, rtol=2e-3)
    tangent = np.stack([-pos[:, 1], pos[:, 0]], axis=1) / radius[:, None]
    motion = np.sign(np.sum(np.diff(pos[:, :2], axis=0) * tangent[:-1], axis=1))
    assert np.all(motion == motion[0])  # drives one way round
    heading_error = np.degrees(np.arccos(np.clip(np.sum(fwd[:, :2] * tangent * motion[0], axis=1), -1, 1)))
    assert heading_error.max() < 0.5
    assert np.allclose(fwd[:, 2], 0, atol=1e-9)  # stays level


def test_open_curve_stops_at_its_end(blender, tmp_path):
    scene = blender.context.scene
    scene.render.fps, scene.frame_start, scene.frame_end = 10, 1, 50
    _vehicle(blender, tmp_path)
    _curve(blender, [(0, 0, 0), (10, 0, 0)])
    scene.frame_set(1)
    blender.ops.symdrive.follow_curve(curve="path", speed=5.0)
    root = blender.context.active_object
    fcurve_frames = {int(k.co[0]) for fc in compat.object_fcurves(root) for k in fc.keyframe_points}
    assert fcurve_frames == set(range(1, 22))  # 10 m at 0.5 m per frame


def test_key_pose_by_hand(blender, tmp_path):
    root = _vehicle(blender, tmp_path)
    scene = blender.context.scene
    scene.frame_set(1)
    root.location = (0, 0, 0.75)
    blender.ops.symdrive.key_pose()
    scene.frame_set(11)
    root.location, root.rotation_euler = (10, 0, 0.75), (0, 0, math.pi / 2)
    blender.ops.symdrive.key_pose()
    scene.frame_set(1)
    assert tuple(root.location) == pytest.approx((0, 0, 0.75))
    scene.frame_set(11)
    assert root.rotation_euler.z == pytest.approx(math.pi / 2)


def test_sumo_fcd_drives_matching_actors(blender, tmp_path):
    scene = blender.context.scene
    scene.render.fps, scene.frame_start, scene.frame_end = 10, 1, 40
    root = _vehicle(blender, tmp_path, actor_id="veh0")
    steps = []
    for i in range(21):  # t = 0.5 .. 2.5 s: east at 10 m/s for 1 s, then north
        t = 0.5 + 0.1 * i
        x, y, angle = (10 * (t - 0.5), 0.0, 90.0) if t <= 1.5 else (10.0, 10 * (t - 1.5), 0.0)
        steps.append(
            f'<timestep time="{t:.2f}"><vehicle id="veh0" x="{x:.3f}" y="{y:.3f}" '
            f'angle="{angle}" speed="10" lane="e_0"/></timestep>'
        )
    fcd = tmp_path / "fcd.xml"
    fcd.write_text('<?xml version="1.0"?>\n<fcd-export>' + "".join(steps) + "</fcd-export>\n")
    assert blender.ops.symdrive.import_sumo_fcd(filepath=str(fcd)) == {"FINISHED"}
    half = root.symdrive.wlh[1] / 2
    scene.frame_set(6)  # t = 0.5 s: departs at the origin heading east
    np.testing.assert_allclose(
        root.matrix_world.translation, (-half, 0, root.symdrive.ground_offset), atol=1e-5
    )
    assert not root.hide_render
    scene.frame_set(21)  # t = 2.0 s: heading north, bumper at (10, 5)
    np.testing.assert_allclose(root.matrix_world.translation[:2], (10, 5 - half), atol=1e-5)
    np.testing.assert_allclose(root.matrix_world.col[0][:3], (0, 1, 0), atol=1e-6)
    scene.frame_set(3)  # before departure and after arrival: absent
    assert root.hide_render
    scene.frame_set(30)
    assert root.hide_render


def test_package_poses_key_matching_actors(blender, tmp_path, make_package):
    manifest_path = make_package(n_frames=4)
    _vehicle(blender, tmp_path, actor_id="car_0", flip_forward=True)
    root = blender.context.active_object
    assert blender.ops.symdrive.import_package_poses(filepath=str(manifest_path)) == {"FINISHED"}
    from blender_addon import actors
    from symdrive_core.scene import load_manifest

    m = load_manifest(manifest_path)
    for i, pose in enumerate(m.actors[0].poses):
        blender.context.scene.frame_set(1 + i)
        np.testing.assert_allclose(np.array(actors.asset_world_matrix(root)), pose.matrix(), atol=1e-5)
