"""Resampling clips between frame rates (30/60/120 Hz streams and datasets)."""

from __future__ import annotations

import numpy as np

from motion_style_ros.core import kernels, rotations as rot
from motion_style_ros.core.motion import Motion


def resample(motion: Motion, fps: float) -> Motion:
    """The clip at ``fps``: rotations by slerp, translations linearly, same start and duration.

    Output frame k sits at time k / fps and interpolates the two input frames around it. This is an
    offline operation on a whole clip; streams resample frame by frame in the runtime.
    """
    if fps == motion.fps:
        return motion
    if not (np.isfinite(fps) and fps > 0):
        raise ValueError(f"target frame rate must be positive, got {fps}")
    n_out = int(np.floor((motion.n_frames - 1) * fps / motion.fps + 1e-9)) + 1
    src = np.arange(n_out) * (motion.fps / fps)
    i0 = np.minimum(np.floor(src).astype(int), motion.n_frames - 1)
    i1 = np.minimum(i0 + 1, motion.n_frames - 1)
    a = src - i0
    q = rot.make_continuous(motion.rotations)
    rotations = rot.slerp(q[i0], q[i1], np.broadcast_to(a[:, None], (n_out, q.shape[1])))
    positions = motion.positions[i0] + a[:, None, None] * (motion.positions[i1] - motion.positions[i0])
    return Motion(motion.skeleton, rotations, positions, fps)


def at_speed(motion: Motion, speed: float) -> Motion:
    """The clip played ``speed`` times as fast, at its own frame rate."""
    return resample(Motion(motion.skeleton, motion.rotations, motion.positions, motion.fps * speed), motion.fps)


class Hermite:
    """A stream's frames between its last two frames ``(t, rotations, positions)``, C1 across
    frames with no look ahead; call it with a time in between.

    Each frame's tangent is its backward difference (from the frame before it), so the segment that
    ends at a frame and the one that starts there share its velocity, and a segment needs nothing
    after its end: the same latency as linear interpolation. With two frames only, both tangents
    are their difference (linear). Rotations are interpolated as rotation vectors relative to the
    segment's first frame (``q0 exp(r(s))``), which keeps the angular velocity continuous too. The
    logarithms are taken once per segment; each time in between costs one exponential.
    """

    def __init__(self, frames: list[tuple[float, np.ndarray, np.ndarray]]) -> None:
        (self.t0, q0, self.p0), (t1, q1, self.p1) = frames[-2], frames[-1]
        self._shape, self.span = q0.shape, t1 - self.t0
        self._q0 = _rows(q0)
        if len(frames) >= 3:
            tp, qp, pp = frames[-3]
            ratio = self.span / (self.t0 - tp)
            self._r1, self._r0 = kernels.hermite_tangents(self._q0, _rows(q1), _rows(qp), ratio)
            self.v0 = ratio * (self.p0 - pp)
        else:  # both tangents the difference: linear
            self._r1 = self._r0 = kernels.hermite_tangents(self._q0, _rows(q1), _rows(q1), 0.0)[0]
            self.v0 = self.p1 - self.p0

    def __call__(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        s = min(max(float((t - self.t0) / self.span), 0.0), 1.0)  # every streamed output frame: no np.clip
        s2, s3 = s * s, s * s * s
        a, b, c, d = 2 * s3 - 3 * s2 + 1, s3 - 2 * s2 + s, -2 * s3 + 3 * s2, s3 - s2  # x0, m0, x1, m1
        rotations = kernels.hermite_rotations(self._q0, self._r0, self._r1, b, c + d).reshape(self._shape)
        return rotations, a * self.p0 + b * self.v0 + c * self.p1 + d * (self.p1 - self.p0)


def _rows(q: np.ndarray) -> np.ndarray:
    return kernels.rows(q).reshape(-1, 4)


def hermite(frames: list[tuple[float, np.ndarray, np.ndarray]], t: float) -> tuple[np.ndarray, np.ndarray]:
    """:class:`Hermite` of ``frames`` at ``t`` (one time)."""
    return Hermite(frames)(t)
