"""The compiled per-pose kernels against SciPy and against the numpy rotation maths they replace
in a streamed frame (no data, no ROS)."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from motion_style_ros.core import feature_kernels, jit, rotations as rot
from motion_style_ros.io import joint_state
from motion_style_ros.core.features import facing_yaw
from motion_style_ros.core.motion import forward_kinematics, rest_positions
from motion_style_ros.core.skeleton import canonical

RNG = np.random.default_rng(0)


def random_quats(*shape: int) -> np.ndarray:
    return rot.normalize(RNG.normal(size=shape + (4,)))


def scipy_of(q: np.ndarray) -> Rotation:
    return Rotation.from_quat(q[..., [1, 2, 3, 0]])


@pytest.mark.parametrize("lead", [(), (1,), (5,), (3, 4)])
def test_forward_kinematics_composes_parents_like_scipy(lead):
    sk = canonical()
    q = random_quats(*lead, sk.n_joints)
    roots = RNG.normal(size=lead + (3,))
    g_rot, g_pos = forward_kinematics(sk, q, rest_positions(sk, roots))
    assert g_rot.shape == lead + (sk.n_joints, 4) and g_pos.shape == lead + (sk.n_joints, 3)
    flat_q, flat_root = q.reshape(-1, sk.n_joints, 4), roots.reshape(-1, 3)
    for r in range(len(flat_q)):
        world = [None] * sk.n_joints
        pos = np.zeros((sk.n_joints, 3))
        for j, p in enumerate(sk.parents):
            local = scipy_of(flat_q[r, j])
            offset = flat_root[r] if j == sk.pelvis else sk.offsets[j]
            world[j] = local if p < 0 else world[p] * local
            pos[j] = offset if p < 0 else pos[p] + world[p].apply(offset)
        np.testing.assert_allclose(g_pos.reshape(-1, sk.n_joints, 3)[r], pos, atol=1e-12)
        got = scipy_of(g_rot.reshape(-1, sk.n_joints, 4)[r])
        np.testing.assert_allclose(got.as_matrix(), np.stack([w.as_matrix() for w in world]), atol=1e-12)
    # a subset of joints' rotations, as the foot lock asks for them
    sub, _ = forward_kinematics(sk, q, rest_positions(sk, roots), joints=[sk.pelvis, 3])
    np.testing.assert_array_equal(sub, g_rot[..., [sk.pelvis, 3], :])


def test_facing_yaw_is_the_heading_of_hips_and_shoulders():
    sk = canonical()
    g = RNG.normal(size=(7, sk.n_joints, 3))
    ul, ur, al, ar = (sk.index(n) for n in ("UpperLeg_L", "UpperLeg_R", "UpperArm_L", "UpperArm_R"))
    across = (g[:, ul] - g[:, ur]) + (g[:, al] - g[:, ar])
    forward = np.cross(across, [0.0, 1.0, 0.0])
    np.testing.assert_allclose(facing_yaw(g, sk), np.arctan2(forward[:, 0], forward[:, 2]), atol=1e-14)
    assert facing_yaw(g[2:3].reshape(1, 1, sk.n_joints, 3), sk).shape == (1, 1)


def test_pose_helpers_equal_the_numpy_rotation_maths():
    q = random_quats(50)
    v = RNG.normal(size=(50, 3))
    d6 = RNG.normal(size=(50, 6))
    six = np.empty(6)
    for k in range(50):
        out = np.empty(4)
        feature_kernels._from_6d(d6[k], 0, out)
        assert np.abs(out - rot.from_6d(d6[k])).max() < 1e-12
        feature_kernels._six(q[k], six, 0)
        np.testing.assert_allclose(six, rot.to_6d(q[k]), atol=1e-12)
        rotated = np.empty(3)
        jit.rotate_vector(q[k], v[k], rotated)
        np.testing.assert_allclose(rotated, rot.rotate(q[k], v[k]), atol=1e-12)
        jit.qmul(q[k], q[-k - 1], out)
        np.testing.assert_allclose(out, rot.multiply(q[k], q[-k - 1]), atol=1e-12)


@pytest.mark.parametrize("u, v", [
    (np.array([0.3, -1.0, 0.2]), np.array([1.0, 0.5, -0.4])),  # any two directions
    (np.array([0.0, 0.0, 2.0]), np.array([0.0, 0.0, -1.0])),  # opposite: about an orthogonal axis
    (np.array([1.0, 1.0, 0.0]), np.array([-2.0, -2.0, 0.0])),  # opposite, ties in the least-used axis
    (np.array([0.5, 0.1, 0.0]), np.array([0.5, 0.1, 0.0])),  # the same: the identity
])
def test_between_takes_u_onto_v_as_the_numpy_one_does(u, v):
    q = np.empty(4)
    jit.quat_between(u, v, q)
    np.testing.assert_allclose(q, rot.between(u, v), atol=1e-12)
    np.testing.assert_allclose(rot.rotate(q, u / np.linalg.norm(u)), v / np.linalg.norm(v), atol=1e-12)


def test_layout_angles_are_rep103_xyz_euler_like_scipy_and_invert():
    core_to_ros = np.array([[0, 0, 1], [1, 0, 0], [0, 1, 0]], dtype=float)  # core (x, y, z) -> ROS (z, x, y)
    q = random_quats(50)
    locked = Rotation.from_euler("XYZ", [[0.3, np.pi / 2, 0.2], [0.1, -np.pi / 2, 0.5]]).as_matrix()  # in ROS axes
    q[:2] = Rotation.from_matrix(core_to_ros.T @ locked @ core_to_ros).as_quat()[:, [3, 0, 1, 2]]
    angles = joint_state.euler_rows(q)
    ros = Rotation.from_matrix(core_to_ros @ scipy_of(q).as_matrix() @ core_to_ros.T)
    back = Rotation.from_euler("XYZ", angles)  # intrinsic X-Y-Z, as the layout documents
    np.testing.assert_allclose((back.inv() * ros).magnitude(), 0.0, atol=1e-9)
    np.testing.assert_allclose(angles[2:], ros[2:].as_euler("XYZ"), atol=1e-9)
    assert abs(angles[0, 2]) < 1e-12 and abs(angles[1, 2]) < 1e-12  # locked: the third angle is 0
    again = joint_state.quat_rows(angles)
    np.testing.assert_allclose(np.abs(np.sum(again * q, axis=-1)), 1.0, atol=1e-9)  # q or -q


def test_layout_values_and_poses_invert_each_other():
    sk = canonical()
    q = random_quats(7, sk.n_joints)
    q[:, :sk.pelvis] = [1.0, 0.0, 0.0, 0.0]  # above the pelvis: static, as in a stream
    roots = RNG.normal(size=(7, 3))
    values = joint_state.layout_values(q, roots, sk.pelvis)
    assert values.shape == (7, 3 + 3 * (sk.n_joints - sk.pelvis))
    np.testing.assert_array_equal(values[:, :3], roots[:, [2, 0, 1]])
    rotations, back = joint_state.layout_poses(values, sk.pelvis)
    np.testing.assert_allclose(back, roots, atol=1e-15)
    np.testing.assert_allclose(np.abs(np.sum(rotations * q, axis=-1)), 1.0, atol=1e-9)
