"""The procedural performer: a plausible walk, run and wave on the canonical skeleton."""

import numpy as np
import pytest

from motion_style_ros.core.retarget import tpose
from motion_style_ros.core.skeleton import canonical
from motion_style_ros.core.synthetic import KINDS, synthetic_motion
from motion_style_ros.errors import MotionStyleError

FPS = 60


@pytest.fixture(scope="module")
def clips():
    return {k: synthetic_motion(k, FPS, 4.0) for k in KINDS}


def joint(motion, name):
    return motion.global_positions()[:, motion.skeleton.index(name)]


@pytest.mark.parametrize("kind", KINDS)
def test_shape_rate_and_feet_on_the_floor(clips, kind):
    m = clips[kind].check_finite()
    assert m.skeleton.names == canonical().names and m.fps == FPS and m.n_frames == 4 * FPS
    feet = m.global_positions()[:, list(m.skeleton.feet), 1]
    floor = tpose(canonical()).positions[list(m.skeleton.feet), 1].min()
    np.testing.assert_allclose(feet.min(axis=1), floor, atol=1e-6)  # the lower foot on the floor
    head = joint(m, "Head")[:, 1]
    assert head.min() > 1.2  # upright


@pytest.mark.parametrize("kind", ["walk", "run"])
def test_legs_counterphase_arms_opposite_and_pelvis_forward(clips, kind):
    m = clips[kind]
    thigh_l = joint(m, "LowerLeg_L")[:, 2] - joint(m, "UpperLeg_L")[:, 2]  # knee ahead of hip
    thigh_r = joint(m, "LowerLeg_R")[:, 2] - joint(m, "UpperLeg_R")[:, 2]
    hand_l = joint(m, "Hand_L")[:, 2] - joint(m, "UpperArm_L")[:, 2]
    assert np.corrcoef(thigh_l, thigh_r)[0, 1] < -0.8
    assert np.corrcoef(hand_l, thigh_r)[0, 1] > 0.9
    speed = np.diff(m.root_positions[:, 2]) * FPS
    assert speed.min() > 0.5 and np.ptp(speed) < 1e-9  # steady progress along +Z (forward)
    assert np.abs(m.root_positions[:, 0]).max() < 0.05  # no drift sideways


def test_stance_foot_stays_nearly_planted_while_walking(clips):
    m = clips["walk"]
    pelvis_speed = np.diff(m.root_positions[:, 2]).mean() * FPS
    ankles = np.stack([joint(m, "Foot_L"), joint(m, "Foot_R")], axis=1)
    lower = np.argmin(ankles[:, :, 1], axis=1)
    velocity = np.gradient(ankles[:, :, [0, 2]], axis=0) * FPS
    stance_speed = np.linalg.norm(velocity[np.arange(len(lower)), lower], axis=-1)
    assert np.median(stance_speed) < 0.5 * pelvis_speed


def test_run_is_faster_and_bends_the_knees_more(clips):
    walk, run = clips["walk"], clips["run"]
    assert run.root_positions[-1, 2] > 1.5 * walk.root_positions[-1, 2]
    knee_height = [joint(m, "LowerLeg_L")[:, 1].max() for m in (walk, run)]
    assert knee_height[1] > knee_height[0]


def test_wave_lifts_the_right_hand_and_moves_it(clips):
    m = clips["wave"]
    hand_r, hand_l, head = joint(m, "Hand_R"), joint(m, "Hand_L"), joint(m, "Head")
    assert (hand_r[:, 1] > head[:, 1]).all() and (hand_l[:, 1] < head[:, 1] - 0.3).all()
    assert np.ptp(hand_r[:, 0]) > 0.1  # side to side
    assert np.ptp(m.root_positions[:, [0, 2]], axis=0).max() < 1e-9  # standing in place


@pytest.mark.parametrize("kind", KINDS)
def test_chunks_join_seamlessly(kind):
    whole = synthetic_motion(kind, 30, 2.0)
    first, second = synthetic_motion(kind, 30, 1.0), synthetic_motion(kind, 30, 1.0, start=1.0)
    np.testing.assert_allclose(np.concatenate([first.rotations, second.rotations]), whole.rotations,
                               atol=1e-12)
    np.testing.assert_allclose(np.concatenate([first.positions, second.positions]), whole.positions,
                               atol=1e-12)


def test_bad_arguments():
    with pytest.raises(MotionStyleError, match="unknown synthetic motion 'dance'"):
        synthetic_motion("dance")
    with pytest.raises(MotionStyleError, match="fps > 0"):
        synthetic_motion("walk", fps=0)
