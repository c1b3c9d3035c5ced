"""Rotation maths against SciPy and against its own inverses (no data, no ROS)."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from motion_style_ros.core import rotations as rot

RNG = np.random.default_rng(0)


def random_quats(n: int) -> np.ndarray:
    return rot.normalize(RNG.normal(size=(n, 4)))


def scipy_of(q: np.ndarray) -> Rotation:
    return Rotation.from_quat(q[..., [1, 2, 3, 0]])


def test_multiply_and_rotate_match_scipy():
    a, b = random_quats(100), random_quats(100)
    v = RNG.normal(size=(100, 3))
    ab = rot.multiply(a, b)
    assert np.allclose(rot.to_matrix(ab), (scipy_of(a) * scipy_of(b)).as_matrix(), atol=1e-12)
    assert np.allclose(rot.rotate(a, v), scipy_of(a).apply(v), atol=1e-12)
    assert np.allclose(rot.rotate(rot.conjugate(a), rot.rotate(a, v)), v, atol=1e-12)


@pytest.mark.parametrize("order", ["ZXY", "ZYX", "XYZ", "YXZ", "XZY", "YZX"])
def test_euler_round_trip_any_order(order):
    angles = RNG.uniform(-170, 170, size=(200, 3))
    angles[:, 1] = RNG.uniform(-85, 85, size=200)  # away from gimbal lock
    q = rot.from_euler(angles, order, degrees=True)
    assert np.allclose(rot.to_matrix(q), Rotation.from_euler(order, angles, degrees=True).as_matrix(), atol=1e-12)
    back = rot.to_euler(q, order, degrees=True)
    assert np.allclose(back, angles, atol=1e-8)


@pytest.mark.parametrize("order", ["ZXY", "XYZ", "YZX", "ZYX"])
def test_euler_at_gimbal_lock_composes_back(order):
    angles = RNG.uniform(-170, 170, size=(20, 3))
    angles[:10, 1], angles[10:, 1] = 90.0, -90.0
    q = rot.from_euler(angles, order, degrees=True)
    back = rot.to_euler(q, order, degrees=True)
    assert np.allclose(back[:, 2], 0.0)  # the first angle takes the whole turn
    assert np.allclose(rot.to_matrix(rot.from_euler(back, order, degrees=True)), rot.to_matrix(q), atol=1e-6)


def test_small_and_large_batches_agree():
    """One streamed frame takes the matrix forms, a clip the elementwise ones: same numbers."""
    a, b = random_quats(600), random_quats(600)
    v = RNG.normal(size=(600, 3))
    for small in (slice(0, 1), slice(0, 22), slice(0, 256)):
        assert np.allclose(rot.multiply(a[small], b[small]), rot.multiply(a, b)[small], atol=1e-14)
        assert np.allclose(rot.rotate(a[small], v[small]), rot.rotate(a, v)[small], atol=1e-14)
    assert np.allclose(rot.rotate(a[:1], v), scipy_of(a[:1]).apply(v), atol=1e-12)  # broadcast


def test_matrix_and_6d_round_trip():
    q = random_quats(300)
    assert np.allclose(np.abs(np.sum(rot.from_matrix(rot.to_matrix(q)) * q, axis=-1)), 1.0)
    assert np.allclose(rot.angle_between(rot.from_6d(rot.to_6d(q)), q), 0.0, atol=1e-6)
    # Any 6-vector maps to a proper rotation.
    m = rot.matrix_from_6d(RNG.normal(size=(50, 6)))
    assert np.allclose(np.linalg.det(m), 1.0)
    assert np.allclose(m @ np.swapaxes(m, -1, -2), np.eye(3), atol=1e-12)


def test_between_including_opposite_vectors():
    u = RNG.normal(size=(100, 3))
    v = RNG.normal(size=(100, 3))
    v[:3] = -u[:3]
    q = rot.between(u, v)
    out = rot.rotate(q, u / np.linalg.norm(u, axis=-1, keepdims=True))
    assert np.allclose(out, v / np.linalg.norm(v, axis=-1, keepdims=True), atol=1e-9)


def test_slerp_endpoints_midpoint_and_short_arc():
    a, b = random_quats(50), random_quats(50)
    assert np.allclose(rot.angle_between(rot.slerp(a, b, 0.0), a), 0, atol=1e-6)
    assert np.allclose(rot.angle_between(rot.slerp(a, b, 1.0), b), 0, atol=1e-6)
    mid = rot.slerp(a, -b, 0.5)  # sign of b must not matter
    assert np.allclose(rot.angle_between(a, mid), rot.angle_between(a, b) / 2, atol=1e-6)


def test_make_continuous_removes_sign_flips():
    q = random_quats(1)[0]
    track = np.stack([q, -q, q, -q])
    cont = rot.make_continuous(track)
    assert np.all(np.sum(cont[1:] * cont[:-1], axis=-1) > 0)


def test_yaw_is_about_up_axis():
    q = rot.from_yaw(np.array(np.pi / 2))
    assert np.allclose(rot.rotate(q, np.array([0.0, 0.0, 1.0])), [1.0, 0.0, 0.0], atol=1e-12)


def test_log_and_exp_match_scipy_rotation_vectors_and_invert_each_other():
    q = random_quats(200)
    v = rot.log(q)
    np.testing.assert_allclose(v, scipy_of(q).as_rotvec(), atol=1e-9)
    assert np.abs(rot.angle_between(rot.exp(v), q)).max() < 1e-9
    tiny = np.array([[1e-12, 0.0, 0.0], [0.0, 0.0, 0.0]])
    np.testing.assert_allclose(rot.log(rot.exp(tiny)), tiny, atol=1e-15)
