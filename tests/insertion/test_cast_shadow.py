"""Cast shadows from a vehicle's Gaussians: the shadow map against a float64 ray-marching oracle,
its geometry, the hard cases, and the darkening it applies."""

import numpy as np
import pytest

from symdrive_core.conventions import srgb_to_linear
from symdrive_core.gaussians import Gaussians, logit
from symdrive_core.shadows.cast import darken, occlusion_image, shadow_map

from . import synthetic


def _gaussians(means, scales, quats=None, opacities=None) -> Gaussians:
    n = len(means)
    quats = np.tile([1.0, 0, 0, 0], (n, 1)) if quats is None else quats
    opacities = np.full(n, 0.6) if opacities is None else opacities
    return Gaussians(np.asarray(means, np.float32), np.asarray(quats, np.float32),
                     np.log(np.asarray(scales, np.float64)).astype(np.float32), logit(opacities),
                     np.zeros((n, 1, 3), np.float32))


def _sun(elevation_deg: float, azimuth_deg: float) -> np.ndarray:
    e, a = np.deg2rad(elevation_deg), np.deg2rad(azimuth_deg)
    return np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), -np.sin(e)])


def _oracle(g: Gaussians, sun, ground_xy: np.ndarray, ground_z: float) -> np.ndarray:
    """1 - prod(1 - o * max response) with the maximum found by marching each ray to the sun
    (alphas under 1/255 dropped, as the rasterizer drops them)."""
    s = np.asarray(sun, np.float64) / np.linalg.norm(sun)
    q = g.unit_quats.astype(np.float64)
    w, x, y, z = q.T
    R = np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
                  2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
                  2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1).reshape(-1, 3, 3)
    prec = np.einsum("nij,nj,nkj->nik", R, 1 / g.scales.astype(np.float64) ** 2, R)
    out = []
    steps = np.linspace(0.0, 30.0, 30001)
    for p in ground_xy:
        ray = np.array([p[0], p[1], ground_z])[None] - steps[:, None] * s  # towards the sun
        T = 1.0
        for mu, P, o in zip(g.means.astype(np.float64), prec, g.opacities.astype(np.float64)):
            d = ray - mu
            peak = np.exp(-0.5 * np.einsum("ri,ij,rj->r", d, P, d).min())
            a = min(0.99, o * peak)
            T *= 1.0 - (a if a >= 1.0 / 255.0 else 0.0)
        out.append(1.0 - T)
    return np.array(out)


def test_shadow_map_matches_ray_marching_oracle():
    rng = np.random.default_rng(3)
    n = 6
    means = np.column_stack([rng.uniform(-0.8, 0.8, n), rng.uniform(-0.5, 0.5, n), rng.uniform(0.3, 1.4, n)])
    scales = rng.uniform(0.12, 0.5, (n, 3))
    quats = rng.normal(size=(n, 4))
    g = _gaussians(means, scales, quats, rng.uniform(0.3, 0.9, n))
    sun = _sun(40.0, 25.0)
    smap = shadow_map(g, sun, 0.0)
    pts = np.column_stack([rng.uniform(-1.0, 3.0, 40), rng.uniform(-1.0, 2.0, 40)])
    np.testing.assert_allclose(smap.sample(pts), _oracle(g, sun, pts, 0.0), atol=3e-3)


def test_shadow_falls_away_from_the_sun_at_the_right_distance():
    h, elev = 2.0, 30.0
    g = _gaussians([[0.0, 0.0, h]], [[0.2, 0.2, 0.2]], opacities=np.array([0.8]))
    smap = shadow_map(g, _sun(elev, 0.0), 0.0)
    reach = h / np.tan(np.deg2rad(elev))  # along +x, where the light travels
    assert smap.sample(np.array([[reach, 0.0]]))[0] == pytest.approx(0.8, abs=5e-3)
    assert smap.sample(np.array([[0.0, 0.0]]))[0] < 1e-3  # nothing under the blob itself
    overhead = shadow_map(g, [0.0, 0.0, -1.0], 0.0)
    assert overhead.sample(np.array([[0.0, 0.0]]))[0] == pytest.approx(0.8, abs=5e-3)


def test_sun_at_or_below_horizon_casts_nothing():
    g = _gaussians([[0.0, 0.0, 1.0]], [[0.3, 0.3, 0.3]])
    assert shadow_map(g, [1.0, 0.0, 0.0], 0.0) is None
    assert shadow_map(g, [1.0, 0.0, 0.2], 0.0) is None
    with pytest.raises(ValueError, match="sun_direction"):
        shadow_map(g, [0.0, 0.0, 0.0], 0.0)


def test_flat_splat_edge_on_to_the_sun_stays_finite():
    # A surfel in the x-z plane, sun travelling along x: it projects to a segment (singular cover).
    g = _gaussians([[0.0, 0.0, 1.0]], [[0.4, 1e-9, 0.4]], opacities=np.array([0.9]))
    smap = shadow_map(g, _sun(45.0, 90.0), 0.0)
    assert np.isfinite(smap.occlusion).all() and smap.occlusion.max() > 0.5
    tiny = shadow_map(_gaussians([[0.0, 0.0, 1.0]], [[1e-7, 1e-7, 1e-7]]), _sun(45.0, 0.0), 0.0)
    assert np.isfinite(tiny.occlusion).all()


def test_far_from_origin_gives_the_same_shadow():
    rng = np.random.default_rng(5)
    means = np.column_stack([rng.uniform(-1, 1, 8), rng.uniform(-1, 1, 8), rng.uniform(0.3, 1.5, 8)])
    scales = rng.uniform(0.1, 0.4, (8, 3))
    sun = _sun(35.0, 140.0)
    pts = np.column_stack([rng.uniform(-2, 2, 30), rng.uniform(-2, 2, 30)])
    near = shadow_map(_gaussians(means, scales), sun, 0.0).sample(pts)
    shift = np.array([3.0e4, -2.0e4, 0.0])
    # float32 means 3e4 m out hold about 2 mm: the shadow moves by that at most
    far = shadow_map(_gaussians(means + shift, scales), sun, 0.0).sample(pts + shift[:2])
    np.testing.assert_allclose(far, near, atol=2e-2)
    assert near.max() > 0.3


def test_occlusion_image_reads_the_map_at_each_pixels_ground_point():
    cam = synthetic.camera()
    g = _gaussians([synthetic.car_pose().translation], [[0.8, 0.6, 0.5]], opacities=np.array([0.95]))
    smap = shadow_map(g, [0.0, 0.0, -1.0], 0.0)
    occ = occlusion_image(smap, cam.camera_to_world, cam.K, cam.width, cam.height)
    assert occ.shape == (cam.height, cam.width) and occ.max() > 0.5
    assert (occ == 0).mean() > 0.5  # most of the image is far from the blob's shadow


def test_darken_scales_linear_radiance_and_leaves_the_rest_bit_identical():
    rng = np.random.default_rng(0)
    bg = rng.uniform(0.05, 0.95, (6, 7, 3)).astype(np.float32)
    image = bg.copy()
    image[0, 0] = [1.0, 0.0, 0.0]  # a vehicle pixel
    alpha = np.zeros((6, 7), np.float32)
    alpha[0, 0] = 1.0
    occ = np.zeros((6, 7), np.float32)
    occ[:3, :3] = 1.0
    occ[4, 4] = 0.5
    out = darken(image, bg, alpha, occ, 0.4)
    untouched = occ == 0
    assert np.array_equal(out[untouched], image[untouched])
    np.testing.assert_array_equal(out[0, 0], image[0, 0])
    np.testing.assert_allclose(srgb_to_linear(out[1, 1]), 0.4 * srgb_to_linear(bg[1, 1]), rtol=1e-4)
    np.testing.assert_allclose(srgb_to_linear(out[4, 4]), 0.7 * srgb_to_linear(bg[4, 4]), rtol=1e-4)
    with pytest.raises(ValueError, match="shadow_ratio"):
        darken(image, bg, alpha, occ, 1.5)


def test_no_shadow_on_what_stands_in_front_of_the_ground():
    cam = synthetic.camera()
    g = _gaussians([synthetic.car_pose().translation], [[0.8, 0.6, 0.5]], opacities=np.array([0.95]))
    smap = shadow_map(g, [0.0, 0.0, -1.0], 0.0)
    args = (cam.camera_to_world, cam.K, cam.width, cam.height)
    bare = occlusion_image(smap, *args)
    # the ground's own depth (what a render of the bare ground gives), then a wall in the left half
    from symdrive_core.shadows.region import ground_hits

    xy, hit = ground_hits(*args, 0.0)
    pts = np.concatenate([xy, np.zeros(xy.shape[:-1] + (1,))], -1)
    ground_depth = np.where(hit, (pts @ cam.world_to_camera[:3, :3].T + cam.world_to_camera[:3, 3])[..., 2], 0.0)
    np.testing.assert_array_equal(occlusion_image(smap, *args, ground_depth * 1.02), bare)
    walled = ground_depth.copy()
    walled[:, : cam.width // 2] *= 0.6
    occ = occlusion_image(smap, *args, walled)
    assert (occ[:, : cam.width // 2] == 0).all() and bare[:, : cam.width // 2].max() > 0.1
    np.testing.assert_array_equal(occ[:, cam.width // 2:], bare[:, cam.width // 2:])


def test_a_huge_floater_does_not_wash_out_the_cars_shadow():
    from symdrive_core.scene.place import place
    from symdrive_core.shadows.cast import shadow_window

    pose, sun = synthetic.car_pose(), _sun(40.0, 60.0)
    car = place(synthetic.car(800), pose)
    floater = _gaussians([pose.translation + [0.0, 0.0, 3.0]], [[1e4, 1e4, 1e4]], opacities=np.array([0.01]))
    with_floater = Gaussians(*(np.concatenate([getattr(car, k), getattr(floater, k)])
                               for k in ("means", "quats", "log_scales", "opacity_logits", "sh")))
    window = shadow_window(pose, synthetic.WLH, sun)
    clean = shadow_map(car, sun, 0.0, bounds=window)
    dirty = shadow_map(with_floater, sun, 0.0, bounds=window)
    assert dirty.cell == clean.cell <= 0.02 and np.isfinite(dirty.occlusion).all()
    # the floater adds its own faint 1 % everywhere, and nothing else
    np.testing.assert_allclose(dirty.occlusion, 1 - (1 - clean.occlusion) * 0.99, atol=2e-3)
    assert clean.occlusion.max() > 0.9
