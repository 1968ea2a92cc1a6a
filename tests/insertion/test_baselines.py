import numpy as np

from symdrive_core.insertion.baselines import (
    background_ring,
    lab_to_rgb,
    naive,
    reinhard_transfer,
    rgb_to_lab,
)


def test_lab_round_trip():
    rgb = np.random.default_rng(0).uniform(0.05, 0.95, (20, 3))
    np.testing.assert_allclose(lab_to_rgb(rgb_to_lab(rgb)), rgb, atol=1e-6)


def test_reinhard_matches_ring_statistics_and_leaves_the_rest_alone():
    rng = np.random.default_rng(1)
    img = np.empty((40, 40, 3))
    img[:] = 0.35 + 0.1 * rng.random((40, 40, 1)) * np.array([1.0, 0.9, 1.2])
    alpha = np.zeros((40, 40))
    alpha[12:28, 10:30] = 1.0
    img[alpha > 0] = np.array([0.8, 0.1, 0.1]) + 0.05 * rng.random((int(alpha.sum()), 3))
    out = reinhard_transfer(img, alpha, ring=6)
    car, ring = alpha > 0.5, background_ring(alpha > 0.5, 6)
    lab_out, lab_in = rgb_to_lab(out), rgb_to_lab(img)
    np.testing.assert_allclose(lab_out[car].mean(0), lab_in[ring].mean(0), atol=2e-3)
    np.testing.assert_allclose(lab_out[car].std(0), lab_in[ring].std(0), atol=2e-3)
    np.testing.assert_array_equal(out[~car], img[~car].astype(np.float32))
    np.testing.assert_array_equal(naive(img), img.astype(np.float32))


def test_reinhard_without_a_vehicle_is_the_identity():
    img = np.full((8, 8, 3), 0.4)
    np.testing.assert_array_equal(reinhard_transfer(img, np.zeros((8, 8))), img.astype(np.float32))
