"""Standing performers keep the input's root motion; walking ones keep the stylizer's."""

import numpy as np

from motion_style_ros.core.features import feature_layout
from motion_style_ros.core.skeleton import canonical
from motion_style_ros.core.standing import ROOT_MOTION, Standing

FPS = 30.0


def frames(left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """Input features with the root moving at 0.1 m/s and the given per-frame foot contacts."""
    sk = canonical()
    lay = feature_layout(sk)
    f = np.zeros((len(left), lay.size))
    f[:, 0] = 0.1
    columns = np.arange(lay.slices["contact"].start, lay.slices["contact"].stop)
    for column, joint in zip(columns, sk.feet):
        f[:, column] = left if sk.names[joint].endswith("_L") else right
    return f


def run(features: np.ndarray) -> np.ndarray:
    """Root velocity x of a stylizer that walks at 1 m/s, through Standing."""
    standing = Standing(1, FPS)
    output = np.zeros((1, 10))
    output[0, 0] = 1.0
    return np.array([standing(output, f[None])[0, 0] for f in features])


def test_a_performer_standing_still_keeps_the_inputs_root_motion():
    n = 90
    vx = run(frames(np.ones(n), np.ones(n)))
    hold = int(0.5 * FPS)
    assert np.allclose(vx[:hold - 1], 1.0)  # not yet: a double support is not standing
    assert np.allclose(vx[hold + 10:], 0.1)  # eased over 0.3 s to the input's
    assert np.abs(np.diff(vx)).max() <= 1.5 * 0.9 / (0.3 * FPS) + 1e-9  # no jump (smoothstep: slope 1.5 at most)
    assert ROOT_MOTION == [0, 1, 3]


def test_walking_keeps_the_stylizers_speed_and_stepping_off_eases_back():
    t = np.arange(120)
    left = (t % 30 < 18).astype(float)  # a walk: 0.2 s of double support per step
    right = ((t + 15) % 30 < 18).astype(float)
    assert np.allclose(run(frames(left, right)), 1.0)
    # Standing for 2 s, then walking off: back to the stylizer's speed, eased.
    both = np.r_[np.ones(60), left[:60]]
    vx = run(frames(both, np.r_[np.ones(60), right[:60]]))
    assert np.isclose(vx[59], 0.1) and np.isclose(vx[-1], 1.0)
    assert np.abs(np.diff(vx)).max() <= 1.5 * 0.9 / (0.3 * FPS) + 1e-9
