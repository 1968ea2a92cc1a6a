"""The ground plane under the camera path, on a street with kerbs, wide sidewalks and facades."""

from __future__ import annotations

import numpy as np
import pytest

from symdrive_core.importers.ground import AlignmentError, alignment, fit_ground
from symdrive_core.importers.similarity import apply_camera, apply_points, make_similarity
from symdrive_core.rotations import quat_normalize, quat_to_matrix

from ..conftest import look_at_c2w


def street(rng, n=20000):
    """Road |y| < 3.5 at z = 0, sidewalks 3.5 < |y| < 12 at z = 0.15 (more points than the road),
    facades at |y| = 12, parked-car roofs at z = 1.4; cameras at 1.6 m along +x."""
    x = rng.uniform(-10, 60, n)
    y = rng.uniform(-12, 12, n)
    z = np.where(np.abs(y) < 3.5, 0.0, 0.15) + rng.normal(0, 0.005, n)
    facade = np.stack([rng.uniform(-10, 60, n // 2), rng.choice([-12.0, 12.0], n // 2), rng.uniform(0, 15, n // 2)], 1)
    roofs = np.stack([rng.uniform(0, 50, 2000), rng.uniform(2.6, 3.4, 2000), np.full(2000, 1.4)], 1)
    pts = np.concatenate([np.stack([x, y, z], 1), facade, roofs])
    cams = np.stack([look_at_c2w((i, -1.75, 1.6), (i + 10, -1.75, 1.5)) for i in range(30)])
    return pts, cams


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_road_not_sidewalk_nor_facade(seed):
    rng = np.random.default_rng(seed)
    pts, cams = street(rng)
    R = quat_to_matrix(quat_normalize(rng.normal(size=4)))
    S = make_similarity(0.37, R, rng.normal(size=3) * 400)
    src_pts, src_cams = apply_points(S, pts), np.stack([apply_camera(S, c) for c in cams])
    ground = fit_ground(src_pts, src_cams)
    T, rec = alignment(ground, src_cams, camera_height=1.6)
    out = np.stack([apply_camera(T, c) for c in src_cams])
    assert abs(rec["scale"] * 0.37 - 1) < 2e-3
    np.testing.assert_allclose(out[:, 2, 3], 1.6, atol=5e-3)
    np.testing.assert_allclose(out[:, :3, 2] @ [0, 0, 1], cams[:, :3, 2] @ [0, 0, 1], atol=1e-3)


def test_no_points_below_the_cameras_says_how_to_pass_up():
    rng = np.random.default_rng(0)
    pts, cams = street(rng)
    with pytest.raises(AlignmentError, match="--up"):
        fit_ground(pts[pts[:, 2] > 2.0], cams)


def test_given_up_fixes_the_normal():
    rng = np.random.default_rng(4)
    pts, cams = street(rng)
    ground = fit_ground(pts, cams, up=(0, 0, 1))
    np.testing.assert_allclose(ground.normal, [0, 0, 1])
    assert abs(np.median(ground.camera_heights) - 1.6) < 5e-3


def _angle_deg(a, b) -> float:
    return float(np.degrees(np.arccos(np.clip(np.dot(a, b), -1.0, 1.0))))


@pytest.mark.parametrize("seed", [0, 1])
def test_curved_drive_one_plane_whatever_the_frame_or_order(seed, tmp_path):
    """The fit is deterministic and every threshold is relative: a similarity of the input (scale
    0.37) and a shuffle of the points give the same plane, mapped."""
    from .curved_street import CAMERA_HEIGHT, curved_world

    world, parts = curved_world(tmp_path, seed=seed)
    ground = fit_ground(world.points, world.c2w)
    true_up = world.S[:3, :3] @ [0.0, 0.0, 1.0]
    assert _angle_deg(ground.normal, true_up) < 0.05
    assert abs(np.median(ground.camera_heights) / CAMERA_HEIGHT - 1) < 0.005
    rng = np.random.default_rng(seed)
    S = make_similarity(0.37, quat_to_matrix(quat_normalize(rng.normal(size=4))), rng.normal(size=3) * 300)
    perm = rng.permutation(len(world.points))
    moved = fit_ground(apply_points(S, world.points[perm]), np.stack([apply_camera(S, c) for c in world.c2w]))
    assert _angle_deg(moved.normal, S[:3, :3] @ ground.normal / 0.37) < 1e-5  # float64 round-off of a 300 m move
    np.testing.assert_allclose(moved.camera_heights, 0.37 * ground.camera_heights, rtol=1e-9)
    assert moved.inliers == ground.inliers and moved.corridor_points == ground.corridor_points
    # the kerbs, cars and facades are off the plane: the inliers are road points
    on = np.abs(ground.height(world.points)) < 0.05
    assert on[parts["road"]].mean() > 0.9 and on[parts["kerbs"]].mean() < 0.01 and on[parts["cars"]].mean() < 0.05


def test_a_rough_ground_is_reported_weak():
    rng = np.random.default_rng(3)
    pts, cams = street(rng)
    road = np.abs(pts[:, 1]) < 3.5
    rough = pts.copy()
    rough[road, 2] += rng.normal(0, 0.2, road.sum())  # 20 cm of scatter: no plane to trust
    _, sound = alignment(fit_ground(pts, cams), cams, camera_height=1.6)
    _, weak = alignment(fit_ground(rough, cams), cams, camera_height=1.6)
    assert sound["ground_fit"]["weak"] == [] and sound["ground_fit"]["residual_rms_m"] < 0.01
    assert any("residual RMS" in w for w in weak["ground_fit"]["weak"]), weak["ground_fit"]


def test_scale_and_camera_height_place_the_ground_below_the_cameras():
    rng = np.random.default_rng(5)
    pts, cams = street(rng)
    ground = fit_ground(pts, cams)
    T, rec = alignment(ground, cams, camera_height=1.55, scale=1.0)
    z = np.stack([apply_camera(T, c) for c in cams])[:, 2, 3]
    assert abs(np.median(z) - 1.55) < 1e-9  # placed, not fitted: the cameras ride at 1.6 over the road
    np.testing.assert_allclose(z, 1.55, atol=1e-3)  # the fitted normal keeps them level
    assert rec["scale"] == 1.0 and abs(rec["ground_fit"]["fitted_camera_height_m"] - 1.6) < 5e-3
    assert rec["ground_fit"]["weak"] == []  # 3 % off the fit: within what a stated camera height may be off
    _, rec = alignment(ground, cams, camera_height=1.2, scale=1.0)
    assert "fitted plane" in rec["ground_fit"]["weak"][0]


def test_without_points_up_and_camera_height_place_the_ground():
    rng = np.random.default_rng(6)
    _, cams = street(rng)
    cams[:, 2, 3] += np.linspace(0, 0.5, len(cams))  # a slope: the lowest camera is not the reference
    T, rec = alignment(None, cams, camera_height=1.65, up=(0, 0, 1))
    z = np.stack([apply_camera(T, c) for c in cams])[:, 2, 3]
    assert rec["scale"] == 1.0 and abs(np.median(z) - 1.65) < 1e-9
    with pytest.raises(AlignmentError, match="--up"):
        alignment(None, cams, camera_height=1.65)


def test_mostly_clutter_under_the_path_still_finds_the_road(tmp_path):
    """A queue of vehicles in the lane puts more points under the path than the road has: the
    start at the road's depth and the inliers' robust scale keep the plane on the road, and the
    low share of points on it is reported."""
    from .curved_street import CAMERA_HEIGHT, LANE, _arc, curved_world

    world, _ = curved_world(tmp_path, seed=4)
    rng = np.random.default_rng(4)
    phi = rng.uniform(0, 1.2, 600)
    queue = np.column_stack([_arc(phi, LANE + rng.uniform(-0.9, 0.9, 600)), rng.uniform(0.1, 1.4, 600)])
    pts = np.concatenate([world.points, apply_points(world.S, queue)])
    _, rec = alignment(fit_ground(pts, world.c2w), world.c2w, camera_height=CAMERA_HEIGHT)
    assert abs(rec["scale"] - 1) < 0.005, rec
    q = rec["ground_fit"]
    assert q["inlier_fraction"] < 0.3 and any("points under the path on it" in w for w in q["weak"]), q


def test_path_up_ignores_the_cameras_pitch():
    """A camera pitched 3 degrees down on a road climbing 2 %: the up from the path is the road's
    normal, not the cameras' up; on a curve too."""
    from symdrive_core.importers.ground import path_up

    def c2w(position, forward, pitch_deg):
        f = np.asarray(forward, float) / np.linalg.norm(forward)
        left = np.cross([0.0, 0.0, 1.0], f)
        left /= np.linalg.norm(left)
        a = np.deg2rad(pitch_deg)
        f = np.cos(a) * f - np.sin(a) * np.cross(f, left)  # pitched down
        up = np.cross(f, left)
        m = np.eye(4)
        m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = -left, -up, f, position  # OpenCV: x right, y down, z forward
        return m

    road = np.array([-0.02, 0.0, 1.0]) / np.linalg.norm([-0.02, 0.0, 1.0])  # climbing 2 % along +x
    straight = np.stack([c2w([x, 0.0, 0.02 * x + 1.6], [1.0, 0.0, 0.02], 3.0) for x in np.linspace(0, 50, 26)])
    assert np.degrees(np.arccos(np.clip(path_up(straight) @ road, -1, 1))) < 0.01
    t = np.linspace(0, np.pi / 2, 30)
    curve = np.stack([c2w([30 * np.sin(a), 30 * (1 - np.cos(a)), 1.6], [np.cos(a), np.sin(a), 0.0], 3.0) for a in t])
    assert np.degrees(np.arccos(np.clip(path_up(curve)[2], -1, 1))) < 0.01
