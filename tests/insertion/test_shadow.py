import numpy as np

from symdrive_core import conventions
from symdrive_core.scene import Pose
from symdrive_core.shadows.region import (
    convex_hull,
    dilate,
    harmonization_region,
    inside_convex,
    shadow_polygon,
    shadow_region,
)

from . import synthetic

WLH = synthetic.WLH


def test_sun_overhead_shadow_is_the_footprint():
    pose = Pose(np.array([5.0, 1.0, WLH[2] / 2]), np.array([1.0, 0, 0, 0]))
    hull = shadow_polygon(pose, WLH, [0.0, 0.0, -1.0])
    lo, hi = hull.min(0), hull.max(0)
    np.testing.assert_allclose(lo, [5 - WLH[1] / 2, 1 - WLH[0] / 2])
    np.testing.assert_allclose(hi, [5 + WLH[1] / 2, 1 + WLH[0] / 2])


def test_low_sun_stretches_the_shadow_away_from_the_sun():
    pose = Pose(np.array([0.0, 0.0, WLH[2] / 2]), np.array([1.0, 0, 0, 0]))
    elev = np.deg2rad(30.0)
    sun = np.array([np.cos(elev), 0.0, -np.sin(elev)])  # light travels towards +x
    hull = shadow_polygon(pose, WLH, sun)
    reach = WLH[1] / 2 + WLH[2] / np.tan(elev)
    assert np.isclose(hull[:, 0].max(), reach) and np.isclose(hull[:, 0].min(), -WLH[1] / 2)


def test_no_sun_or_sun_below_horizon_gives_no_region():
    cam = synthetic.camera()
    pose = synthetic.car_pose()
    args = (cam.camera_to_world, cam.K, cam.width, cam.height)
    assert shadow_region(pose, WLH, None, *args) is None
    assert shadow_region(pose, WLH, [0.3, 0.0, 0.5], *args) is None


def test_region_covers_projected_ground_points_and_grows_with_dilation():
    cam = synthetic.camera(width=96, height=60)
    pose = synthetic.car_pose()
    sun = np.array([0.4, -0.5, -0.77])
    args = (cam.camera_to_world, cam.K, cam.width, cam.height)
    hull = shadow_polygon(pose, WLH, sun)
    region = shadow_region(pose, WLH, sun, *args, dilate_px=0)
    # Points sampled inside the ground polygon land on region pixels.
    rng = np.random.default_rng(0)
    w = rng.dirichlet(np.ones(len(hull)), size=200)
    pts = np.concatenate([w @ hull, np.zeros((200, 1))], 1)
    uv, z = conventions.project_points(pts, cam.world_to_camera, cam.K)
    ok = (z > 0) & (uv[:, 0] >= 0.5) & (uv[:, 0] < cam.width - 0.5) & (uv[:, 1] >= 0.5) & (uv[:, 1] < cam.height - 0.5)
    assert ok.sum() > 50
    hits = region[np.floor(uv[ok, 1]).astype(int), np.floor(uv[ok, 0]).astype(int)]
    assert hits.mean() > 0.95
    grown = shadow_region(pose, WLH, sun, *args, dilate_px=3)
    assert grown.sum() > region.sum() and np.all(grown[region])


def test_hull_and_inside_and_dilate():
    sq = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0.5, 0.5]], dtype=float)
    hull = convex_hull(sq)
    assert len(hull) == 4
    assert inside_convex(np.array([[0.5, 0.2], [1.5, 0.5]]), hull).tolist() == [True, False]
    m = np.zeros((9, 9), bool)
    m[4, 4] = True
    assert dilate(m, 2).sum() == 25 and dilate(m, 0).sum() == 1


def test_harmonization_region_is_vehicle_union_shadow():
    alpha = np.zeros((10, 10))
    alpha[2:4, 2:4] = 1.0
    shadow = np.zeros((10, 10), bool)
    shadow[7:9, 7:9] = True
    region = harmonization_region(alpha, shadow, dilate_px=0)
    assert region.sum() == 8
    assert harmonization_region(alpha, None, dilate_px=1).sum() == 16
