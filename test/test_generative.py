"""The ESANN 2018 seed's generative measures (motion_style_ros.evaluation.generative) on small
cases whose answers are known in closed form."""

import numpy as np
import pytest

from motion_style_ros.errors import MotionStyleError
from motion_style_ros.evaluation import generative as gen


def test_parzen_of_one_sample_is_the_gaussian_density():
    rng = np.random.default_rng(0)
    sample, test = rng.normal(size=(1, 4)), rng.normal(size=(5, 4))
    sigma = 0.7
    expected = (-((test - sample) ** 2).sum(1) / (2 * sigma**2) - 2 * np.log(2 * np.pi * sigma**2))
    mean, sem = gen.parzen_log_likelihood(test, sample, sigma)
    assert mean == pytest.approx(expected.mean(), abs=1e-10)
    assert sem == pytest.approx(expected.std(ddof=1) / np.sqrt(5), abs=1e-10)


def test_parzen_mixes_its_samples_and_keeps_far_points_finite():
    samples = np.array([[0.0], [2.0]])
    sigma = 0.5
    x = np.array([[1.0]])
    density = 0.5 * 2 * np.exp(-1 / (2 * sigma**2)) / np.sqrt(2 * np.pi * sigma**2)
    assert gen.parzen_log_likelihood(x, samples, sigma)[0] == pytest.approx(np.log(density), abs=1e-10)
    # 1000 sigmas away: exp underflows, the log-sum-exp does not
    far = gen.parzen_log_likelihood(np.array([[500.0]]), samples, sigma)[0]
    assert np.isfinite(far) and far == pytest.approx(-(498.0**2) / (2 * sigma**2) - np.log(2)
                                                      - 0.5 * np.log(2 * np.pi * sigma**2), rel=1e-9)


def test_parzen_prefers_samples_from_the_test_distribution_and_picks_a_sensible_width():
    rng = np.random.default_rng(1)
    test, val = rng.normal(size=(200, 3)), rng.normal(size=(200, 3))
    good, bad = rng.normal(size=(500, 3)), rng.normal(3.0, 1.0, size=(500, 3))
    sigma = gen.parzen_bandwidth(val, good)
    assert 0.2 < sigma < 1.5
    assert gen.parzen_log_likelihood(test, good, sigma)[0] > gen.parzen_log_likelihood(test, bad, sigma)[0] + 1


def test_g2t_and_t2g_on_known_points():
    true = np.array([[0.0, 0.0], [10.0, 0.0]])
    assert gen.g2t(true, true) == 0.0 and gen.t2g(true, true) == 0.0
    # every generated point near the first true point: realistic (G2T 1) but a mode missed (T2G big)
    collapsed = np.array([[0.0, 1.0], [1.0, 0.0]])
    assert gen.g2t(collapsed, true) == pytest.approx(1.0)
    assert gen.t2g(collapsed, true) == pytest.approx((1.0 + 9.0) / 2)
    assert np.allclose(gen.nearest_distances(np.array([[3.0, 4.0]]), true), [5.0])


def test_windows_become_normalised_vectors_and_bad_shapes_are_one_line():
    w = np.arange(24, dtype=float).reshape(2, 3, 4)
    v = gen.as_vectors(w, mean=np.full(4, 1.0), std=np.full(4, 2.0))
    assert v.shape == (2, 12) and v[0, 0] == -0.5 and v[1, -1] == 11.0
    with pytest.raises(MotionStyleError, match="expected"):
        gen.g2t(np.zeros((2, 3)), np.zeros((2, 4)))
    with pytest.raises(MotionStyleError, match="sigma"):
        gen.parzen_log_likelihood(np.zeros((1, 2)), np.zeros((1, 2)), 0.0)


def test_the_papers_figures_rank_a_faithful_generator_above_a_collapsed_one():
    rng = np.random.default_rng(2)
    clips = [np.cumsum(rng.normal(size=(60, 3)), axis=0) for _ in range(12)]
    windows = gen.clip_windows(clips, 8, 4, channels=2)
    assert windows.shape == (12 * 14, 8, 2)
    assert np.array_equal(windows[1], clips[0][4:12, :2])
    test, val, faithful = windows[0::3], windows[1::3], windows[2::3]
    collapsed = np.repeat(faithful[:1], len(faithful), axis=0)
    good, bad = gen.measures(faithful, test, val), gen.measures(collapsed, test, val)
    assert good["parzen_log_likelihood"] > bad["parzen_log_likelihood"]
    assert good["t2g"] < bad["t2g"] and good["dims"] == 16
    with pytest.raises(MotionStyleError, match="no clip"):
        gen.clip_windows(clips, 61, 1)
