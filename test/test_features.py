"""Causal features and their inverse, and resampling, on real Bandai clips."""

import numpy as np
import pytest

from motion_style_ros.core import features as F
from motion_style_ros.core import rotations as rot
from motion_style_ros.core.motion import Motion
from motion_style_ros.core.resample import resample
from motion_style_ros.core.skeleton import canonical, cmu31
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io import bvh

DATA2 = "bandai-namco/Bandai-Namco-Research-Motiondataset-2/data/"


@pytest.fixture(scope="module")
def turn(datasets) -> Motion:
    m = bvh.read(datasets / DATA2 / "dataset-2_walk-turn-left_elderly_010.bvh").to_motion(0.01)
    return Motion.from_rotations(canonical(), m.rotations, m.positions[:, 1], m.fps)


def test_layout_sizes():
    lay = F.feature_layout()
    assert len(lay.joints) == 21 and 0 not in lay.joints
    assert lay.size == 4 + 21 * 12 + 4


def test_features_are_causal(turn):
    full = F.encode(turn)
    for t in (1, 2, 17, 60):
        assert np.array_equal(F.encode(turn[:t]), full[:t])


def test_decode_inverts_encode(turn):
    f = F.encode(turn)
    g = turn.global_positions()
    yaw0 = F.facing_yaw(g[:1], turn.skeleton)[0]
    back = F.decode(f, turn.fps, start_ground=g[0, 1], start_yaw=yaw0)
    # float32 features: micrometres after integrating a whole clip.
    assert np.abs(back.global_positions() - g).max() < 1e-4


def test_features_ignore_where_and_which_way_the_performer_stands(turn):
    turned = rot.from_yaw(np.array(1.3))
    rotations = turn.rotations.copy()
    rotations[:, 1] = rot.multiply(turned, rotations[:, 1])
    root = rot.rotate(turned, turn.positions[:, 1]) + [3.0, 0.0, -2.0]
    moved = Motion.from_rotations(turn.skeleton, rotations, root, turn.fps)
    assert np.abs(F.encode(moved) - F.encode(turn)).max() < 1e-4


def test_root_velocity_and_contacts_are_plausible(turn):
    f = F.encode(turn)
    lay = F.feature_layout()
    root = f[:, lay.slices["root"]]
    speed = np.linalg.norm(root[:, :2], axis=-1).mean()
    assert 0.2 < speed < 2.0  # an elderly walk, m/s
    assert root[:, 3].mean() > 0.1  # turning left: yaw increases about +Y
    contacts = f[:, lay.slices["contact"]]
    assert 0.2 < contacts.mean() < 0.9  # walking: each foot is planted part of the time


def test_features_need_the_canonical_skeleton():
    sk = cmu31()
    m = Motion.from_rotations(sk, rot.identity((3, sk.n_joints)), np.zeros((3, 3)), 120.0)
    with pytest.raises(MotionStyleError, match="retarget"):
        F.encode(m)


def test_resample_keeps_duration_and_round_trips(turn):
    up = resample(turn, 120.0)
    assert up.fps == 120.0 and up.n_frames == (turn.n_frames - 1) * 4 + 1
    # Every 4th frame is an original frame.
    assert np.allclose(up.global_positions()[::4], turn.global_positions(), atol=1e-9)
    down = resample(up, 30.0)
    assert np.allclose(down.global_positions(), turn.global_positions(), atol=1e-9)
    mid = resample(turn, 60.0).global_positions()[1::2]
    g = turn.global_positions()
    assert np.abs(mid - (g[:-1] + g[1:]) / 2).max() < 0.02  # between its neighbours
