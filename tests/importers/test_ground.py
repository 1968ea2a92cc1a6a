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
