"""A performer's size, read from how their root moves against their legs.

A stream in the canonical layout carries joint rotations and the root's position in metres, not
bone lengths: a performer 0.8 times the canonical skeleton's size sends the same rotations with a
root that moves 0.8 times as far per step. A stylizer that took that root as it is would see a
canonical body whose planted feet slide backwards (and a pelvis that sinks), and its output, put
back on the performer's smaller avatar, would slide the other way.

While a foot is planted, the world velocity of its ankle is zero: the root moves at minus the
performer's scale times the rate at which the canonical leg carries the ankle relative to the
pelvis, ``v_root = -s * d/dt(ankle - pelvis)``. The scale is the least-squares ``s`` over such
frames (the stance foot is the one that moves least at the current estimate), with a prior of 1
worth :data:`PRIOR_WEIGHT` so that a stream with no steps in it keeps the canonical size.
:class:`StreamScale` maps the stream into canonical proportions (root displacements divided by
``s``) and the stylized output back (multiplied by ``s``), so the output keeps the
performer's own proportions.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from motion_style_ros.core import jit
from motion_style_ros.core.motion import Motion

PRIOR_WEIGHT = 0.5  # (m/s)^2 frames: a few steps outweigh it
MIN_LEG_SPEED = 0.1  # m/s: slower relative ankle motion says little about the scale
SCALE_RANGE = (0.5, 2.0)
# A frame counts when its stance ankle moves, at the current estimate, slower than this fraction
# of the leg's own motion: in a flight phase (runs, jumps) no ankle is planted.
STANCE_RESIDUAL = 0.35
# The points that rest on the floor in a stance: the ankle from heel strike, the toes at push-off
# (the ankle then rolls forward over them).
CONTACTS = ("Foot_L", "Foot_R", "Toes_L", "Toes_R")
RESTART_EVIDENCE = 4.0  # (m/s)^2 frames of stance leg motion: about a step
RESTART_OFF = 0.08  # a first estimate this far from the canonical size is applied at once


def _stance_sums(root_velocity: np.ndarray, leg_velocity: np.ndarray, scale: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The least-squares sums ``(-v . l, l . l)`` of each frame's stance foot: ``root_velocity``
    ``(N, 2)`` and ``leg_velocity`` ``(N, K, 2)`` of the contact points (ankles and toes),
    horizontal m/s (:func:`stance_rows`)."""
    return stance_rows(jit.rows(root_velocity),
                               jit.rows(leg_velocity),
                               jit.rows(scale), MIN_LEG_SPEED, STANCE_RESIDUAL)


def _estimate(cross: np.ndarray, square: np.ndarray, reference: float) -> np.ndarray:
    """The scale from the sums, relative to what the training data gives (``reference``)."""
    low, high = SCALE_RANGE  # np.clip's overhead is more than the maths on one frame
    return np.minimum(np.maximum((cross + PRIOR_WEIGHT * reference) / (square + PRIOR_WEIGHT) / reference, low), high)


def stance_sums(motion: Motion, reference: float = 1.0, passes: int = 3) -> tuple[float, float]:
    """A whole clip's least-squares sums (see the module docstring), the stance feet settled
    together with the scale over a few passes."""
    if motion.n_frames < 2:
        return 0.0, 0.0
    g = motion.global_positions()
    pelvis = motion.skeleton.pelvis
    points = [motion.skeleton.index(n) for n in CONTACTS]
    root_v = np.diff(g[:, pelvis, [0, 2]], axis=0) * motion.fps
    leg_v = np.diff(g[:, points][..., [0, 2]] - g[:, pelvis, None][..., [0, 2]], axis=0) * motion.fps
    scale = reference
    for _ in range(passes):
        cross, square = _stance_sums(root_v, leg_v, np.full(len(root_v), scale))
        scale = reference * float(_estimate(np.array([cross.sum()]), np.array([square.sum()]), reference)[0])
    return float(cross.sum()), float(square.sum())


def clip_scale(motion: Motion, reference: float = 1.0) -> float:
    """A whole clip's performer scale relative to the training data's (``reference``: what
    :func:`stance_sums` gives on it, as ``cross / square`` pooled over its clips)."""
    return float(_estimate(*(np.array([v]) for v in stance_sums(motion, reference)), reference)[0])


class StreamScale:
    """Each of ``performers`` streams' scale, estimated frame by frame, and the maps between the
    stream's world and canonical proportions.

    The map of root positions is kept continuous while the estimate moves (eased with time
    constant ``ease_seconds``): the stream's root displacements are divided by the scale and added
    up from where its first frame was, so a shorter performer's pelvis stays lower by as much as
    it starts: that puts the canonical feet below the floor, which the session's grounding
    (:class:`~motion_style_ros.core.conform.StreamGround`) takes up as it does another rig's ankle
    height, and adds back to the output. :meth:`to_canonical` maps a frame's root in,
    :meth:`observe` learns from it, :meth:`to_stream` maps stylized root positions back out. The
    scale is the rig's: it holds across gaps until :meth:`clear`; :meth:`calibrate` sets it from a
    whole clip.
    """

    def __init__(self, performers: int, fps: float, reference: float = 1.0, ease_seconds: float = 0.2
                 ) -> None:
        self.fps = float(fps)
        self.reference = float(reference)
        self._gain = 1.0 - np.exp(-1.0 / (self.fps * ease_seconds))
        self.scale = np.ones(performers)  # as applied
        self.target = np.ones(performers)
        self._cross = np.zeros(performers)
        self._square = np.zeros(performers)
        self.frozen = np.zeros(performers, dtype=bool)
        self._measured = np.zeros(performers, dtype=bool)  # a first estimate has been applied
        self._stream = np.full((performers, 3), np.nan)  # last frame's root, stream world
        self._canonical = np.zeros((performers, 3))  # and where it went, canonical proportions
        self._relative = np.full((performers, len(CONTACTS), 2), np.nan)  # last contacts - pelvis
        self._step = np.full((performers, 3), np.nan)  # the last frame's root displacement

    def clear(self, which: np.ndarray | slice) -> None:
        """These performers are measured again from nothing (canonical size)."""
        for a, value in ((self.scale, 1.0), (self.target, 1.0), (self._cross, 0.0),
                         (self._square, 0.0), (self._relative, np.nan)):
            a[which] = value
        self.frozen[which] = self._measured[which] = False

    def calibrate(self, performer: int, scale: float) -> None:
        """Fix one performer's scale (a whole clip's, :func:`clip_scale`)."""
        self.scale[performer] = self.target[performer] = scale
        self.frozen[performer] = True

    def start(self, which: np.ndarray) -> None:
        """These performers' streams start (again): the next root is taken as it comes."""
        self._stream[which] = np.nan
        self._relative[which] = np.nan

    def to_canonical(self, root: np.ndarray) -> np.ndarray:
        """A frame's stream roots ``(P, 3)`` in canonical proportions."""
        first = np.isnan(self._stream[:, 0])
        self._step = root - self._stream
        out = np.where(first[:, None], root, self._canonical + self._step / self.scale[:, None])
        self._stream, self._canonical = root.copy(), out.copy()
        return out

    def observe(self, relative_ankles: np.ndarray) -> np.ndarray:
        """Learn from the frame just mapped: its :data:`CONTACTS` relative to the pelvis
        ``(P, K, 3)`` on the canonical skeleton (the rotations alone give them); then ease the
        applied scale on. Returns the performers whose size has just been measured, off the
        canonical one by :data:`RESTART_OFF` or more after :data:`RESTART_EVIDENCE` of leg motion:
        the estimate is applied at once, and a stylizer with a memory can forget the frames
        before (as for the arm rolls)."""
        low, high = SCALE_RANGE
        return observe_scale(
            jit.rows(relative_ankles), self._relative, self._step, self.frozen,
            self._measured, self._cross, self._square, self.target, self.scale, self.fps, self.reference,
            PRIOR_WEIGHT, low, high, MIN_LEG_SPEED, STANCE_RESIDUAL, RESTART_EVIDENCE, RESTART_OFF, self._gain)

    def placed(self, root: np.ndarray) -> np.ndarray:
        """Stream roots ``(P, 3)`` of an earlier frame in canonical proportions, about the latest
        frame's (:meth:`to_stream` gives them back); nothing changes."""
        out = self._canonical + (root - self._stream) / self.scale[:, None]
        return np.where(np.isnan(self._stream[:, :1]), root, out)

    def to_stream(self, positions: np.ndarray) -> np.ndarray:
        """Stylized root positions ``(P, 3)`` (canonical proportions) in the stream's world."""
        out = self._stream + self.scale[:, None] * (positions - self._canonical)
        return np.where(np.isnan(self._stream[:, :1]), positions, out)


@njit(cache=True)
def _stance(root_velocity, leg_velocity, scale, min_speed, residual_fraction):
    """One frame's least-squares sums ``(-v . l, l . l)`` of its stance foot (the contact point
    whose world velocity at this ``scale`` is least; see ``proportions._stance_sums``), or zeros
    where no foot is planted: horizontal root velocity ``(2,)``, contact points' ``(K, 2)``."""
    best, foot = np.inf, 0
    for k in range(leg_velocity.shape[0]):
        w0 = root_velocity[0] + scale * leg_velocity[k, 0]
        w1 = root_velocity[1] + scale * leg_velocity[k, 1]
        moving = w0 * w0 + w1 * w1
        if moving < best:
            best, foot = moving, k
    l0, l1 = leg_velocity[foot, 0], leg_velocity[foot, 1]
    square = l0 * l0 + l1 * l1
    speed = math.sqrt(square)
    if speed > min_speed and math.sqrt(best) < residual_fraction * scale * speed:
        return -(root_velocity[0] * l0 + root_velocity[1] * l1), square
    return 0.0, 0.0


@njit(cache=True)
def stance_rows(root_velocity, leg_velocity, scale, min_speed, residual_fraction):
    """:func:`_stance` of frames: ``(N, 2)``, ``(N, K, 2)``, ``(N,)`` -> the sums ``(N,)`` twice."""
    n = root_velocity.shape[0]
    cross, square = np.empty(n), np.empty(n)
    for r in range(n):
        cross[r], square[r] = _stance(root_velocity[r], leg_velocity[r], scale[r], min_speed, residual_fraction)
    return cross, square


@njit(cache=True)
def observe_scale(relative_points, relative, step, frozen, measured_before, cross, square, target, scale, fps,
                  reference, prior, low, high, min_speed, residual_fraction, evidence, off, gain):
    """:meth:`~motion_style_ros.core.proportions.StreamScale.observe`'s frame, the state arrays
    updated in place: ``relative_points`` ``(P, K, 3)`` the contact points relative to the pelvis,
    ``relative`` ``(P, K, 2)`` the last frame's (horizontal; NaN after a start), ``step`` ``(P, 3)``
    the root's last displacement; the sums ``cross``, ``square``, the estimate ``target`` and the
    applied ``scale`` ``(P,)``. Returns the performers whose size has just been measured."""
    n, k = relative_points.shape[0], relative_points.shape[1]
    have = np.zeros(n, dtype=np.bool_)
    for r in range(n):
        have[r] = not (math.isnan(relative[r, 0, 0]) or math.isnan(step[r, 0]) or frozen[r])
    root_v = np.empty(2)
    leg_v = np.empty((k, 2))
    measured = np.zeros(n, dtype=np.bool_)
    for r in range(n):
        if have[r]:
            for a, c in ((0, 0), (1, 2)):
                root_v[a] = (0.0 if math.isnan(step[r, c]) else step[r, c]) * fps
                for i in range(k):
                    d = relative_points[r, i, c] - relative[r, i, a]
                    leg_v[i, a] = (0.0 if math.isnan(d) else d) * fps
            c_add, s_add = _stance(root_v, leg_v, target[r] * reference, min_speed, residual_fraction)
            cross[r] += c_add
            square[r] += s_add
        if have.any() and not frozen[r]:  # proportions._estimate
            ratio = (cross[r] + prior * reference) / (square[r] + prior) / reference
            target[r] = min(max(ratio, low), high)
        for i in range(k):
            relative[r, i, 0] = relative_points[r, i, 0]
            relative[r, i, 1] = relative_points[r, i, 2]
        if frozen[r]:
            continue
        enough = square[r] >= evidence
        measured[r] = not measured_before[r] and enough and abs(target[r] - scale[r]) >= off
        measured_before[r] = measured_before[r] or enough
        scale[r] += (1.0 if measured[r] else gain) * (target[r] - scale[r])
    return measured
