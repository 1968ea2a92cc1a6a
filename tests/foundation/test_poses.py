import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from symdrive_core.rotations import matrix_to_quat, quat_from_yaw, quat_multiply, quat_slerp, quat_to_matrix
from symdrive_core.scene.poses import Pose, interpolate_pose, yaw_of

quats = st.lists(st.floats(-1, 1, allow_nan=False), min_size=4, max_size=4).filter(
    lambda q: np.linalg.norm(q) > 1e-3)


@settings(max_examples=200, deadline=None)
@given(quats)
def test_quat_matrix_round_trip(q):
    q = np.asarray(q) / np.linalg.norm(q)
    R = quat_to_matrix(q)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    q2 = matrix_to_quat(R)
    assert q2[0] >= 0
    assert min(np.abs(q2 - q).max(), np.abs(q2 + q).max()) < 1e-9  # q and -q are one rotation
    np.testing.assert_allclose(quat_to_matrix(q2), R, atol=1e-12)


@settings(max_examples=100, deadline=None)
@given(quats, quats)
def test_product_matches_matrix_product(a, b):
    np.testing.assert_allclose(quat_to_matrix(quat_multiply(a, b)), quat_to_matrix(a) @ quat_to_matrix(b),
                               atol=1e-12)


def test_yaw_explicit():
    R = quat_to_matrix(quat_from_yaw(np.pi / 2))
    np.testing.assert_allclose(R @ [1, 0, 0], [0, 1, 0], atol=1e-15)  # forward turns to +Y
    assert yaw_of(quat_from_yaw(2.0)) == pytest.approx(2.0)


def test_slerp_endpoints_midpoint_and_short_arc():
    a, b = quat_from_yaw(0.0), quat_from_yaw(np.pi / 2)
    np.testing.assert_allclose(quat_slerp(a, b, 0.0), a, atol=1e-12)
    np.testing.assert_allclose(quat_slerp(a, b, 1.0), b, atol=1e-12)
    np.testing.assert_allclose(quat_slerp(a, b, 0.5), quat_from_yaw(np.pi / 4), atol=1e-12)
    # -b is the same rotation: slerp takes the short way and lands on the same midpoint rotation.
    np.testing.assert_allclose(quat_to_matrix(quat_slerp(a, -b, 0.5)), quat_to_matrix(quat_from_yaw(np.pi / 4)),
                               atol=1e-12)
    near = quat_from_yaw(1e-9)
    assert np.all(np.isfinite(quat_slerp(a, near, 0.3)))


def test_interpolate_pose_linear_translation_and_clamping():
    p0 = Pose(np.array([0.0, 0, 0]), quat_from_yaw(0.0))
    p1 = Pose(np.array([10.0, 2, 0]), quat_from_yaw(1.0))
    mid = interpolate_pose([0.0, 2.0], [p0, p1], 0.5)
    np.testing.assert_allclose(mid.translation, [2.5, 0.5, 0])
    assert yaw_of(mid.rotation) == pytest.approx(0.25)
    assert interpolate_pose([0.0, 2.0], [p0, p1], -1.0) is p0
    assert interpolate_pose([0.0, 2.0], [p0, p1], 5.0) is p1
    with pytest.raises(ValueError, match="increase"):
        interpolate_pose([0.0, 0.0], [p0, p1], 0.0)


def test_pose_compose_and_matrix():
    a = Pose(np.array([1.0, 0, 0]), quat_from_yaw(np.pi / 2))
    b = Pose(np.array([0.0, 2, 0]), quat_from_yaw(0.3))
    np.testing.assert_allclose(a.compose(b).matrix(), a.matrix() @ b.matrix(), atol=1e-12)
    np.testing.assert_allclose(Pose.from_matrix(a.matrix()).rotation, a.rotation, atol=1e-12)
    np.testing.assert_allclose(a.apply([[1.0, 0, 0]]), [[1.0, 1.0, 0]], atol=1e-12)
