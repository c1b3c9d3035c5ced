"""Resampling and the stream's in-between frames (no data, no ROS)."""

import numpy as np

from motion_style_ros.core import rotations as rot
from motion_style_ros.core.resample import hermite

FPS = 30.0


def _frames(n: int) -> list[tuple[float, np.ndarray, np.ndarray]]:
    """A smooth rotation and position curve sampled at model frames: (t, (1, 2, 4), (1, 3))."""
    out = []
    for k in range(n):
        t = k / FPS
        v = np.array([[np.sin(3 * t), 0.8 * t, 0.3 * np.cos(5 * t)], [0.2, -t, 0.1]])
        out.append((t, rot.exp(v)[None], np.array([[np.sin(4 * t), t * t, 0.5]])))
    return out


def _velocity(frames, t: float, eps: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    """Angular (body frame) and linear velocity just before ``t``, from the segment that ends there."""
    a, b = hermite(frames, t - eps), hermite(frames, t)
    return rot.log(rot.multiply(rot.conjugate(a[0]), b[0])) / eps, (b[1] - a[1]) / eps


def _velocity_after(frames, t: float, eps: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
    a, b = hermite(frames, t), hermite(frames, t + eps)
    return rot.log(rot.multiply(rot.conjugate(a[0]), b[0])) / eps, (b[1] - a[1]) / eps


def test_hermite_passes_through_the_frames_and_is_c1_across_them():
    frames = _frames(8)
    for k in range(2, 7):
        t = frames[k][0]
        q, p = hermite(frames[: k + 1], t)  # the segment ending at frame k
        assert np.abs(rot.angle_between(q, frames[k][1])).max() < 1e-9
        np.testing.assert_allclose(p, frames[k][2], atol=1e-12)
        q, p = hermite(frames[: k + 2], t)  # the next segment starts there
        assert np.abs(rot.angle_between(q, frames[k][1])).max() < 1e-9
        w_in, v_in = _velocity(frames[: k + 1], t)
        w_out, v_out = _velocity_after(frames[: k + 2], t)
        assert np.abs(w_in - w_out).max() < 1e-3 * max(1.0, np.abs(w_in).max())
        assert np.abs(v_in - v_out).max() < 1e-3 * max(1.0, np.abs(v_in).max())


def test_hermite_velocity_at_a_frame_is_its_backward_difference():
    """What makes it need nothing after the segment's end: no latency beyond linear interpolation."""
    frames = _frames(5)
    _, v = _velocity(frames[:4], frames[3][0])
    np.testing.assert_allclose(v, (frames[3][2] - frames[2][2]) * FPS, rtol=1e-4)


def test_hermite_with_two_frames_is_linear_and_a_linear_motion_stays_linear():
    frames = _frames(2)
    _, p = hermite(frames, 0.5 / FPS)
    np.testing.assert_allclose(p, 0.5 * (frames[0][2] + frames[1][2]), atol=1e-12)
    q, _ = hermite(frames, 0.5 / FPS)
    assert np.abs(rot.angle_between(q, rot.slerp(frames[0][1], frames[1][1], 0.5))).max() < 1e-9
    # Constant velocity over three frames: the cubic is the straight line.
    line = [(k / FPS, rot.exp(np.array([[0.1 * k, 0.0, 0.0]]))[None], np.array([[0.1 * k, 0.0, 0.0]]))
            for k in range(3)]
    q, p = hermite(line, 1.3 / FPS)
    np.testing.assert_allclose(p, [[0.13, 0.0, 0.0]], atol=1e-12)
    np.testing.assert_allclose(rot.log(q), [[[0.13, 0.0, 0.0]]], atol=1e-12)
