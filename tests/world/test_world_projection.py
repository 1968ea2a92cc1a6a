import numpy as np

from symdrive_core import conventions
from symdrive_core.world.projection import colour_points
from tests.conftest import look_at_c2w


def _view(eye, W=40, H=30):
    K = conventions.intrinsics_from_fov(W, H, np.deg2rad(60))
    c2w = look_at_c2w(eye, (eye[0], eye[1] + 10.0, eye[2]))  # looking along +Y at the wall y = 5
    w2c = conventions.invert_rigid(c2w)
    image = np.zeros((H, W, 3), np.float32)
    image[..., 0] = np.linspace(0, 1, W)[None, :]  # red encodes the column
    depth = np.full((H, W), 5.0 - eye[1], np.float32)  # a wall at y = 5 fills the view
    return K, w2c, image, depth


def test_visible_points_take_their_pixel_colour_and_occluded_ones_are_unseen():
    view = _view(np.array([0.0, 0.0, 1.0]))
    wall = np.array([[0.0, 5.0, 1.0], [1.0, 5.0, 1.0]])
    behind = np.array([[0.0, 8.0, 1.0]])  # hidden by the wall
    outside = np.array([[0.0, -3.0, 1.0]])  # behind the camera
    colours, seen, _ = colour_points(np.concatenate([wall, behind, outside]), [view])
    assert seen.tolist() == [True, True, False, False]
    K, w2c, image, _ = view
    uv, _ = conventions.project_points(wall, w2c, K)
    expected = image[np.floor(uv[:, 1]).astype(int), np.floor(uv[:, 0]).astype(int)]
    assert np.allclose(colours[:2], expected)
    assert colours[1, 0] > colours[0, 0]  # right of centre: redder


def test_the_closest_view_wins():
    near, far = _view(np.array([0.0, 3.0, 1.0])), _view(np.array([0.0, -2.0, 1.0]))
    near[2][...] = 0.7
    colours, seen, dist = colour_points(np.array([[0.0, 5.0, 1.0]]), [far, near])
    assert seen[0] and np.isclose(dist[0], 2.0) and np.allclose(colours[0], 0.7)
