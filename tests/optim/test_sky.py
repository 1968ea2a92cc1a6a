"""Where the sky dome starts in a view without depth: above the horizon and the
skyline the point cloud draws, with the cells, the neighbourhood and the horizon as stated."""

import numpy as np

from symdrive_core.conventions import invert_rigid
from symdrive_core.optim.config import SkyConfig
from symdrive_core.optim.sky import sky_mask
from tests.conftest import look_at_c2w

W, H, F = 160, 96, 80.0
K = np.array([[F, 0.0, W / 2], [0.0, F, H / 2], [0.0, 0.0, 1.0]])
EYE = np.array([0.0, 0.0, 1.6])
WALL_X, WALL_TOP = 20.0, 6.0


def camera() -> np.ndarray:
    """World to camera of a level camera 1.6 m up looking along +x (the horizon at row H / 2)."""
    return invert_rigid(look_at_c2w(EYE, EYE + [1.0, 0.0, 0.0]))


def wall(y_from: float, y_to: float, step: float = 0.25) -> np.ndarray:
    """Points on a wall across the view at x = 20 m, from the road up to 6 m, between y_from and y_to."""
    y, z = np.meshgrid(np.arange(y_from, y_to, step), np.arange(0.0, WALL_TOP + 1e-9, step))
    return np.stack([np.full(y.size, WALL_X), y.ravel(), z.ravel()], 1)


def u_of_y(y: float) -> float:
    """The pixel column of world y on the wall (the camera's x is the world's -y)."""
    return F * (-y) / WALL_X + W / 2


def test_dense_depth_says_where_the_sky_is():
    depth = np.full((H, W), 10.0, np.float32)
    depth[:20] = np.inf
    np.testing.assert_array_equal(sky_mask(depth, K, camera(), W, H, wall(-9, 9), SkyConfig()), np.isinf(depth))


def test_sparse_sensor_depth_gets_no_estimate_and_no_depth_needs_a_cloud():
    sparse = np.full((H, W), np.nan, np.float32)
    sparse[60, 10] = 5.0
    # a scanner's returns draw no skyline: nothing above its top beam is seen, sky or wall
    assert not sky_mask(sparse, K, camera(), W, H, wall(0.5, 9.0), SkyConfig()).any()
    assert not sky_mask(None, K, camera(), W, H, None, SkyConfig()).any()
    assert sky_mask(None, K, camera(), W, H, wall(0.5, 9.0), SkyConfig()).any()


def test_sky_above_the_wall_and_down_to_the_horizon_where_no_point_lands():
    cfg = SkyConfig(cell_px=8, neighbour_cells=0, margin_cells=0, min_elevation_deg=1.0)
    mask = sky_mask(None, K, camera(), W, H, wall(0.5, 9.0), cfg)  # a wall on the left half only
    top_row = F * -(WALL_TOP - EYE[2]) / WALL_X + H / 2  # the wall's top edge: row 30.4
    horizon = H / 2 - F * np.tan(np.radians(1.0))  # 1 degree above the horizon: row 46.6
    left, right = int(u_of_y(5.0)), int(u_of_y(-5.0))
    sky_left = np.nonzero(mask[:, left])[0]
    assert sky_left.max() + 1 == 8 * (int(top_row) // 8)  # down to the cell holding the wall's top
    sky_right = np.nonzero(mask[:, right])[0]
    assert sky_right.min() == 0 and sky_right.max() + 1 == int(np.ceil(horizon))  # open down to the horizon
    assert not mask[int(np.ceil(H / 2)):].any()  # never below the horizon


def test_a_bare_stripe_of_wall_between_textured_ones_is_not_sky():
    points = np.concatenate([wall(-9.0, -2.2), wall(2.2, 9.0)])  # 4.4 m with no point: two empty cells
    stripe = int(u_of_y(0.0))
    alone = sky_mask(None, K, camera(), W, H, points, SkyConfig(neighbour_cells=0))
    assert alone[:int(H / 2) - 2, stripe].all()  # read column by column, the stripe opens to the horizon
    with_neighbours = sky_mask(None, K, camera(), W, H, points, SkyConfig(neighbour_cells=1))
    assert not with_neighbours[24:, stripe].any()  # its neighbours' skyline closes it


def test_points_behind_or_at_the_camera_draw_no_skyline():
    behind = wall(-9.0, 9.0) * [-1.0, 1.0, 1.0]  # the same wall 20 m behind
    mask = sky_mask(None, K, camera(), W, H, behind, SkyConfig())
    assert mask[: int(H / 2) - 2].all()


def test_the_dome_starts_on_the_estimated_sky_only():
    import torch

    from symdrive_core.optim.reconstruct import sky_points
    from symdrive_core.optim.views import View

    image = np.zeros((H, W, 3), np.uint8)
    image[: H // 2] = 200  # the sky's colour, above the horizon
    view = View(0, torch.tensor(K, dtype=torch.float32), torch.tensor(camera(), dtype=torch.float32),
                torch.from_numpy(image), None, W, H, "front")
    rng = np.random.default_rng(0)
    pts, cols = sky_points([view], 500, 100.0, rng, wall(0.5, 9.0))
    assert len(pts) == 500
    direction = (pts - EYE) / 100.0
    np.testing.assert_allclose(np.linalg.norm(pts - EYE, axis=1), 100.0, rtol=1e-5)
    assert direction[:, 2].min() > np.sin(np.radians(1.0)) - 1e-6  # above the horizon
    side = direction[:, 1] / direction[:, 0] * WALL_X  # where the ray crosses the wall's plane
    above_wall = (side > 0.5 + 2.1) & (side < 9.0 - 2.1)  # a cell and its neighbour in from the wall's ends
    assert above_wall.sum() > 20 and (side > 9.0 + 2.1).sum() > 20  # over the wall and beside it
    assert (direction[above_wall, 2] / direction[above_wall, 0] > (WALL_TOP - EYE[2]) / WALL_X - 0.06).all()
    np.testing.assert_allclose(cols, 200 / 255.0)
    assert len(sky_points([view], 500, 100.0, rng, None)[0]) == 0  # no cloud, no depth: no sky claimed


def test_the_command_line_turns_the_skyline_and_the_sensor_dome_off_and_leaves_them_on_by_default(synthetic_package,
                                                                                                  command_config):
    import pytest

    from symdrive_core.cli import main

    seen = [command_config([str(synthetic_package[0]), "--quiet", *extra]).sky
            for extra in ([], ["--no-sky-skyline"], ["--sensor-dome-deg", "0"])]
    default = SkyConfig()
    assert [(s.skyline, s.sensor_dome_deg) for s in seen] == [
        (default.skyline, default.sensor_dome_deg), (False, default.sensor_dome_deg), (default.skyline, 0.0)]
    assert default.skyline and default.sensor_dome_deg > 0
    with pytest.raises(SystemExit):  # an angle below 0 is no size
        main(["reconstruct", str(synthetic_package[0]), "--sensor-dome-deg", "-1"])
