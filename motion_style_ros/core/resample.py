"""Resampling clips between frame rates (30/60/120 Hz streams and datasets)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from motion_style_ros.core import jit
from motion_style_ros.core import rotations as rot
from motion_style_ros.core.jit import EPS, local_rotation, norm3, qmul
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
            self._r1, self._r0 = hermite_tangents(self._q0, _rows(q1), _rows(qp), ratio)
            self.v0 = ratio * (self.p0 - pp)
        else:  # both tangents the difference: linear
            self._r1 = self._r0 = hermite_tangents(self._q0, _rows(q1), _rows(q1), 0.0)[0]
            self.v0 = self.p1 - self.p0

    def __call__(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        s = min(max(float((t - self.t0) / self.span), 0.0), 1.0)  # every streamed output frame: no np.clip
        s2, s3 = s * s, s * s * s
        a, b, c, d = 2 * s3 - 3 * s2 + 1, s3 - 2 * s2 + s, -2 * s3 + 3 * s2, s3 - s2  # x0, m0, x1, m1
        rotations = hermite_rotations(self._q0, self._r0, self._r1, b, c + d).reshape(self._shape)
        return rotations, a * self.p0 + b * self.v0 + c * self.p1 + d * (self.p1 - self.p0)


def _rows(q: np.ndarray) -> np.ndarray:
    return jit.rows(q).reshape(-1, 4)


def hermite(frames: list[tuple[float, np.ndarray, np.ndarray]], t: float) -> tuple[np.ndarray, np.ndarray]:
    """:class:`Hermite` of ``frames`` at ``t`` (one time)."""
    return Hermite(frames)(t)


@njit(cache=True)
def hermite_rotations(q0, r0, r1, b, cd):
    """``q0 exp(b r0 + cd r1)`` of rows (``resample.Hermite``): quaternions ``(N, 4)`` and
    rotation vectors ``(N, 3)`` twice."""
    out = np.empty_like(q0)
    e = np.empty(4)
    for r in range(q0.shape[0]):
        v0 = b * r0[r, 0] + cd * r1[r, 0]
        v1 = b * r0[r, 1] + cd * r1[r, 1]
        v2 = b * r0[r, 2] + cd * r1[r, 2]
        angle = norm3(v0, v1, v2)
        scale = 0.5 if angle < 1e-9 else math.sin(0.5 * angle) / max(angle, 1e-12)  # rotations.exp
        e[0], e[1], e[2], e[3] = math.cos(0.5 * angle), scale * v0, scale * v1, scale * v2
        qmul(q0[r], e, out[r])
    return out


@njit(cache=True)
def _log_between(q0, q1, ratio, out) -> None:
    """``ratio * rotations.log(conjugate(q0) * q1)``: the rotation vector from ``q0`` to ``q1``
    (short arc), scaled, into ``out`` (3,)."""
    q = np.empty(4)
    local_rotation(q0, q1, q)
    n = max(math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]), EPS)
    sign = -1.0 if q[0] / n < 0.0 else 1.0
    w, x, y, z = sign * q[0] / n, sign * q[1] / n, sign * q[2] / n, sign * q[3] / n
    s = norm3(x, y, z)
    scale = 2.0 if s < 1e-9 else 2.0 * math.atan2(s, w) / max(s, 1e-12)
    out[0], out[1], out[2] = ratio * scale * x, ratio * scale * y, ratio * scale * z


@njit(cache=True)
def hermite_tangents(q0, q1, qp, ratio):
    """The rotation vectors of ``resample.Hermite``'s segment from ``q0`` to ``q1`` (rows ``(N,
    4)``): to ``q1``, and ``-ratio`` times the one to the frame before, ``qp``, ``(N, 3)`` each."""
    r1 = np.empty((q0.shape[0], 3))
    r0 = np.empty((q0.shape[0], 3))
    for r in range(q0.shape[0]):
        _log_between(q0[r], q1[r], 1.0, r1[r])
        _log_between(q0[r], qp[r], -ratio, r0[r])
    return r1, r0


# --- JointState layout (io.joint_state): core frame <-> REP-103 Euler angles ----------------------
# REP-103 (x, y, z) are the core's (z, x, y); a rotation maps with its axis.
