"""Evaluation metrics against analytic values on constructed motions and samples."""

import numpy as np
import pytest

from motion_style_ros.core import rotations as rot
from motion_style_ros.core.features import feature_layout
from motion_style_ros.core.motion import Motion
from motion_style_ros.core.skeleton import canonical
from motion_style_ros.evaluation import metrics

FPS = 30.0


def rest_motion(root: np.ndarray, rotations: np.ndarray | None = None) -> Motion:
    """The canonical skeleton holding one pose while its pelvis follows ``root`` (T, 3)."""
    sk = canonical()
    if rotations is None:
        rotations = rot.identity((len(root), sk.n_joints))
    return Motion.from_rotations(sk, rotations, root, FPS)


# --- Frechet distance ---------------------------------------------------------------------------


def test_frechet_distance_of_identical_sets_is_zero():
    a = np.random.default_rng(0).normal(size=(300, 8))
    assert metrics.frechet_distance(a, a) == pytest.approx(0.0, abs=1e-6)


def test_frechet_distance_of_a_shifted_set_is_the_squared_shift():
    a = np.random.default_rng(1).normal(size=(300, 8)) @ np.diag(np.arange(1.0, 9.0))
    shift = np.linspace(-1.0, 2.0, 8)
    assert metrics.frechet_distance(a, a + shift) == pytest.approx(shift @ shift, rel=1e-5)


def test_frechet_distance_of_shifted_gaussians_matches_the_analytic_value():
    rng = np.random.default_rng(2)
    shift = np.array([3.0, 0.0, -4.0, 0.0])  # squared norm 25
    a = rng.normal(size=(20000, 4))
    b = rng.normal(size=(20000, 4)) + shift
    # Same covariance: the distance is the squared mean shift, up to sampling error.
    assert metrics.frechet_distance(a, b) == pytest.approx(25.0, abs=0.3)


def test_frechet_distance_is_symmetric_and_sees_covariance():
    rng = np.random.default_rng(3)
    a = rng.normal(size=(400, 5))
    b = rng.normal(size=(300, 5)) * 2.0 + 0.5
    d = metrics.frechet_distance(a, b)
    assert d == pytest.approx(metrics.frechet_distance(b, a), rel=1e-6)
    # Equal means, scales 1 and 2: trace term 5 * (1 + 4 - 2 * 2) = 5 (+ the mean shift 5 * 0.25).
    assert d == pytest.approx(5.0 + 1.25, rel=0.15)


def test_frechet_distance_of_few_samples_in_many_dimensions_is_finite():
    rng = np.random.default_rng(4)
    d = metrics.frechet_distance(rng.normal(size=(10, 64)), rng.normal(size=(12, 64)))
    assert np.isfinite(d) and d > 0


def test_frechet_distance_rejects_mismatched_sets():
    with pytest.raises(ValueError):
        metrics.frechet_distance(np.zeros((5, 3)), np.zeros((5, 4)))
    with pytest.raises(ValueError):
        metrics.frechet_distance(np.zeros((1, 3)), np.zeros((5, 3)))


# --- jerk ---------------------------------------------------------------------------------------


def test_jerk_of_constant_velocity_is_zero():
    t = np.arange(60) / FPS
    root = np.stack([1.3 * t, np.full_like(t, 0.9), -0.4 * t], axis=-1)
    assert metrics.jerk(rest_motion(root)) == pytest.approx(0.0, abs=1e-6)


def test_jerk_of_a_cubic_trajectory_is_its_third_derivative():
    t = np.arange(60) / FPS
    a = np.array([0.5, -0.2, 0.1])
    root = np.array([0.0, 0.9, 0.0]) + t[:, None] ** 3 * a  # third derivative 6a everywhere
    assert metrics.jerk(rest_motion(root)) == pytest.approx(6 * np.linalg.norm(a), rel=1e-6)


def test_jerk_grows_with_jitter():
    t = np.arange(90) / FPS
    root = np.stack([t, np.full_like(t, 0.9), np.zeros_like(t)], axis=-1)
    noisy = root + np.random.default_rng(5).normal(scale=0.005, size=root.shape)
    assert metrics.jerk(rest_motion(noisy)) > 100 * max(metrics.jerk(rest_motion(root)), 1e-9)


# --- foot skating -------------------------------------------------------------------------------


def test_planted_feet_do_not_skate():
    sk = canonical()
    rotations = rot.from_axis_angle(np.array([0.0, 0.0, 1.0]), np.full((40, sk.n_joints), 0.1))
    rotations[:, 0] = rot.identity()
    assert metrics.foot_skating(rest_motion(np.tile([0.0, 0.9, 0.0], (40, 1)), rotations)) == 0.0


def test_feet_sliding_on_the_ground_skate_at_their_speed_and_lifted_feet_do_not_count():
    speed = 0.7  # m/s on the ground; three times faster while lifted
    t = 90
    lifted = np.zeros(t, dtype=bool)
    lifted[30:60] = True
    step = np.full(t, speed / FPS)
    step[32:58] *= 3.0  # only between lifted frames
    step[0] = 0.0
    root = np.stack([np.cumsum(step), 0.9 + 0.2 * lifted, np.zeros(t)], axis=-1)
    assert metrics.foot_skating(rest_motion(root)) == pytest.approx(speed, rel=1e-9)


def test_foot_skating_is_horizontal_speed_only():
    t = np.arange(60) / FPS
    root = np.stack([0.3 * t, 0.9 + 0.001 * np.sin(t), 0.4 * t], axis=-1)  # 0.5 m/s, mm bobbing
    assert metrics.foot_skating(rest_motion(root)) == pytest.approx(0.5, rel=1e-9)


# --- bone lengths -------------------------------------------------------------------------------


def test_bone_length_error_of_forward_kinematics_is_zero():
    sk = canonical()
    rng = np.random.default_rng(6)
    rotations = rot.normalize(rng.normal(size=(20, sk.n_joints, 4)))
    root = rng.normal(size=(20, 3))
    assert metrics.bone_length_error(rest_motion(root, rotations), sk) == pytest.approx(0.0, abs=1e-12)


def test_bone_length_error_of_a_stretched_bone():
    sk = canonical()
    m = rest_motion(np.tile([0.0, 0.9, 0.0], (10, 1)))
    shin = sk.index("LowerLeg_L")
    m.positions[:, shin] *= 1.1
    n_bones = len(feature_layout(sk).joints) - 1  # every joint below the pelvis ends one bone
    expected = 0.1 * np.linalg.norm(sk.offsets[shin]) / n_bones
    assert metrics.bone_length_error(m, sk) == pytest.approx(expected, rel=1e-9)


# --- content consistency ------------------------------------------------------------------------


def test_content_consistency_is_the_mean_paired_distance():
    a = np.array([[0.0, 0.0], [1.0, 1.0]])
    b = np.array([[3.0, 4.0], [1.0, 1.0]])
    assert metrics.content_consistency(a, b) == pytest.approx(2.5)
    assert metrics.content_consistency(a[0], b[0]) == pytest.approx(5.0)
    with pytest.raises(ValueError):
        metrics.content_consistency(a, b[:1])
