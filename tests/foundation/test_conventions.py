import numpy as np
import pytest

from symdrive_core import conventions as cv


def test_blender_camera_flip_explicit():
    # A Blender camera at the origin with identity rotation looks down world -Z, +Y up in image.
    c2w = cv.blender_camera_to_opencv(np.eye(4))
    np.testing.assert_array_equal(c2w[:3, 0], [1, 0, 0])   # OpenCV x: right
    np.testing.assert_array_equal(c2w[:3, 1], [0, -1, 0])  # OpenCV y: down the image = world -Y
    np.testing.assert_array_equal(c2w[:3, 2], [0, 0, -1])  # OpenCV z: forward = world -Z
    np.testing.assert_array_equal(cv.opencv_camera_to_blender(c2w), np.eye(4))


def test_flip_keeps_translation():
    M = np.eye(4)
    M[:3, 3] = [1.0, 2.0, 3.0]
    np.testing.assert_array_equal(cv.blender_camera_to_opencv(M)[:3, 3], [1, 2, 3])


def test_blender_intrinsics_horizontal_fit_with_shift():
    K = cv.blender_intrinsics(1920, 1080, 50.0, 36.0, 24.0, "AUTO", shift_x=0.1, shift_y=-0.05)
    assert K[0, 0] == pytest.approx(50.0 * 1920 / 36.0)
    assert K[1, 1] == pytest.approx(50.0 * 1920 / 36.0)
    assert K[0, 2] == pytest.approx(960.0 - 0.1 * 1920)
    assert K[1, 2] == pytest.approx(540.0 - 0.05 * 1920)


def test_blender_intrinsics_vertical_fit_and_portrait_auto():
    K = cv.blender_intrinsics(1920, 1080, 50.0, 36.0, 24.0, "VERTICAL")
    assert K[1, 1] == pytest.approx(50.0 * 1080 / 24.0)
    assert (K[0, 2], K[1, 2]) == (960.0, 540.0)
    # AUTO on a portrait image fits the sensor *width* to the image height.
    K = cv.blender_intrinsics(1080, 1920, 50.0, 36.0, 24.0, "AUTO")
    assert K[0, 0] == pytest.approx(50.0 * 1920 / 36.0)


def test_blender_intrinsics_pixel_aspect():
    K = cv.blender_intrinsics(100, 100, 50.0, 36.0, 24.0, "HORIZONTAL", pixel_aspect_x=2.0)
    # 200 aspect-corrected px across 36 mm: fy in square-pixel units, fx halved by the aspect.
    assert K[1, 1] == pytest.approx(50.0 * 200 / 36.0)
    assert K[0, 0] == pytest.approx(K[1, 1] / 2.0)


def test_intrinsics_from_fov_centred_principal_point():
    K = cv.intrinsics_from_fov(640, 360, np.deg2rad(90.0))
    assert K[0, 0] == pytest.approx(320.0)
    assert (K[0, 2], K[1, 2]) == (320.0, 180.0)


def test_pixel_centres_half_offset():
    u, v = cv.pixel_centers(3, 2)
    np.testing.assert_array_equal(u[0], [0.5, 1.5, 2.5])
    np.testing.assert_array_equal(v[:, 0], [0.5, 1.5])


def test_project_principal_point_and_depth():
    K = cv.intrinsics(100.0, 100.0, 16.0, 12.0)
    uv, z = cv.project_points(np.array([[0.0, 0.0, 5.0], [1.0, -1.0, 2.0]]), np.eye(4), K)
    np.testing.assert_allclose(uv[0], [16.0, 12.0])
    np.testing.assert_allclose(uv[1], [16.0 + 50.0, 12.0 - 50.0])
    np.testing.assert_allclose(z, [5.0, 2.0])


def test_lateral_shift_moves_along_camera_right():
    # OpenCV camera looking along world +X with Z up: its right (x) axis is world -Y.
    c2w = np.eye(4)
    c2w[:3, :3] = np.array([[0, 0, 1], [-1, 0, 0], [0, -1, 0]], dtype=float)
    c2w[:3, 3] = [5.0, 1.0, 1.5]
    shifted = cv.lateral_shift(c2w, 2.0)
    np.testing.assert_allclose(shifted[:3, 3], [5.0, -1.0, 1.5])
    np.testing.assert_array_equal(shifted[:3, :3], c2w[:3, :3])


def test_invert_rigid_exact():
    c2w = np.eye(4)
    c2w[:3, :3] = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]], dtype=float)
    c2w[:3, 3] = [1e5, -2e5, 3.0]
    np.testing.assert_allclose(cv.invert_rigid(c2w) @ c2w, np.eye(4), atol=1e-9)


def test_vehicle_frame():
    corners = cv.vehicle_box_corners([1.8, 4.5, 1.5])
    np.testing.assert_allclose(corners.min(0), [-2.25, -0.9, -0.75])
    np.testing.assert_allclose(corners.max(0), [2.25, 0.9, 0.75])
    assert cv.vehicle_ground_offset([1.8, 4.5, 1.5]) == 0.75


def test_bad_sensor_fit_names_the_field():
    with pytest.raises(ValueError, match="sensor_fit"):
        cv.blender_intrinsics(10, 10, 50, 36, 24, "DIAGONAL")


def test_scale_intrinsics_keeps_the_image_edges_fixed():
    K = cv.intrinsics(100.0, 110.0, 64.0, 36.0)  # centred in a 128x72 image
    K2 = cv.scale_intrinsics(K, 0.5)
    np.testing.assert_allclose(K2, [[50.0, 0, 32.0], [0, 55.0, 18.0], [0, 0, 1]])
    # The point that lands on the right edge of the full image lands on the right edge at half size.
    p = np.array([0.64, 0.0, 1.0])
    assert (K @ p)[0] == 128.0 and (K2 @ p)[0] == 64.0
