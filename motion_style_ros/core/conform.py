"""Bring a retargeted motion's joint frames to the conventions of the training data, without
moving a single joint.

Retargeting matches bone *directions*; how a bone's frame is rolled about its own axis comes from
the rigs' T-pose frames, and those disagree (a CMU forearm frame is rolled 36-40 degrees against
Bandai's, so its elbow bends about the "wrong" local axis). Positions cannot see a roll, but a
stylizer that reads local rotations sees it as motion it never met: a retargeted CMU walk was
taken for "raise both hands" until its arm rotations were replaced.

Every canonical bone runs along its joint's local X axis, so turning a joint's frame about X by a
constant angle (and its child's local rotation by the inverse) leaves every position unchanged.
For each arm chain (Shoulder -> UpperArm -> LowerArm -> Hand) the constant rolls that make the
clip's local rotations most typical of the training data (Gaussian 6D-rotation statistics per
joint) are found together by dynamic programming over a grid of angles.

Rigs also disagree on how high the ankle joint sits above the sole: retargeted CMU ankles rest
about 6 cm lower than Bandai's, so the canonical feet sink into the floor and a stylizer takes the
walk for shuffling. :func:`ground` moves the whole clip up or down so that its planted ankles rest
at the training data's height; :class:`StreamGround` does the same causally for a live stream.
"""

from __future__ import annotations

import numpy as np

from motion_style_ros.core import rotations as rot
from motion_style_ros.core.motion import Motion
from motion_style_ros.errors import MotionStyleError

CHAINS = tuple(tuple(f"{j}_{side}" for j in ("Shoulder", "UpperArm", "LowerArm", "Hand"))
               for side in "LR")
STD_FLOOR = 0.05  # 6D components that hardly vary in the training data still allow this much


ANKLES = ("Foot_L", "Foot_R")
PLANTED_PERCENTILE = 5.0  # a clip's planted-ankle height: this percentile of its ankle heights


def statistics(motions: list[Motion]) -> dict[str, np.ndarray]:
    """Per-joint mean and standard deviation of the 6D local rotations ``(J, 6)`` over clips, and
    the median planted-ankle height (m)."""
    d6 = np.concatenate([rot.to_6d(m.rotations) for m in motions])
    return {"names": np.array(motions[0].skeleton.names), "mean": d6.mean(axis=0),
            "std": np.maximum(d6.std(axis=0), STD_FLOOR),
            "ankle_height": np.median([planted_ankle_height(m) for m in motions])}


def planted_ankle_height(motion: Motion) -> float:
    """How high the ankles are when the feet are on the floor: a low percentile of their heights."""
    ankles = [motion.skeleton.index(n) for n in ANKLES]
    return float(np.percentile(motion.global_positions()[:, ankles, 1], PLANTED_PERCENTILE))


def ground(motion: Motion, stats: dict[str, np.ndarray]) -> Motion:
    """``motion`` moved vertically so that its planted ankles rest at ``stats["ankle_height"]``."""
    positions = motion.positions.copy()
    positions[:, motion.skeleton.pelvis, 1] += float(stats["ankle_height"]) - planted_ankle_height(motion)
    return Motion(motion.skeleton, motion.rotations, positions, motion.fps)


def conform(motion: Motion, stats: dict[str, np.ndarray]) -> Motion:
    """A retargeted clip in the training data's conventions: arm rolls and ankle height."""
    return ground(conform_rolls(motion, stats), stats)


def _rolls(steps: int) -> np.ndarray:
    angles = np.arange(steps) * (2 * np.pi / steps)
    return rot.from_axis_angle(np.broadcast_to([1.0, 0.0, 0.0], (steps, 3)), angles)


def conform_rolls(motion: Motion, stats: dict[str, np.ndarray], steps: int = 72,
                  frames: int = 240) -> Motion:
    """``motion`` with constant per-joint rolls about the bone axes (see the module docstring),
    chosen on up to ``frames`` frames spread over the clip; global positions are unchanged to
    rounding."""
    sk = motion.skeleton
    if list(stats["names"]) != list(sk.names):
        raise MotionStyleError("rotation statistics are for another skeleton")
    rolls = _rolls(steps)
    inverse = rot.conjugate(rolls)
    rotations = motion.rotations.copy()
    sample = np.unique(np.linspace(0, motion.n_frames - 1, frames).round().astype(int))
    for chain in CHAINS:
        joints = [sk.index(n) for n in chain]
        # cost[k][a, b]: joint k rolled by b, its parent by a (the chain's first parent, the chest,
        # keeps its frame: a = 0 only).
        costs = []
        for k, j in enumerate(joints):
            parents = inverse[:1] if k == 0 else inverse
            local = rot.multiply(rot.multiply(parents[:, None, None], rotations[None, None, sample, j]),
                                 rolls[None, :, None])  # (A, B, T, 4)
            z = (rot.to_6d(local) - stats["mean"][j]) / stats["std"][j]
            costs.append(np.square(z).sum(axis=(-1, -2)))
        # Viterbi over the chain: best total cost ending with each roll of joint k.
        total = costs[0][0]
        back = []
        for cost in costs[1:]:
            candidates = total[:, None] + cost
            back.append(np.argmin(candidates, axis=0))
            total = candidates.min(axis=0)
        choice = [int(np.argmin(total))]
        for pointer in reversed(back):
            choice.append(int(pointer[choice[-1]]))
        choice.reverse()
        for k, j in enumerate(joints):
            parent_roll = inverse[choice[k - 1]] if k else rot.identity()
            rotations[:, j] = rot.multiply(rot.multiply(parent_roll, rotations[:, j]), rolls[choice[k]])
    return Motion(sk, rotations, motion.positions, motion.fps)


class StreamGround:
    """:func:`ground` for ``performers`` live streams at ``fps``: how far each performer's planted
    ankles rest above ``ankle_height`` (the training data's), so that a session can move the stream
    down by that much before the stylizer and its output back up (the user's floor stays theirs).

    A performer's first frame sets its offset from the lower ankle (:meth:`start`: a stream starts
    with a foot on the floor); then it follows the height of the lower of the ankles that stand
    still (slower than ``speed`` m/s): down within ``down_seconds``, up only over ``up_seconds``
    (a still ankle may be rolling up onto the toes; the floor is the low envelope, as the offline
    percentile takes it).
    """

    def __init__(self, performers: int, fps: float, ankle_height: float, down_seconds: float = 0.2,
                 up_seconds: float = 3.0, speed: float = 0.25) -> None:
        self.ankle_height = float(ankle_height)
        self.speed = speed
        self._fps = float(fps)
        self._down, self._up = (1.0 - np.exp(-1.0 / (self._fps * s)) for s in (down_seconds, up_seconds))
        self._last = np.full((performers, 2, 3), np.nan)
        self.offset = np.zeros(performers)

    def start(self, ankles: np.ndarray, which: np.ndarray) -> None:
        """These performers start afresh with this frame's ankle world positions ``(P, 2, 3)``."""
        self.offset[which] = ankles[which, :, 1].min(axis=-1) - self.ankle_height
        self._last[which] = np.nan

    def update(self, ankles: np.ndarray) -> np.ndarray:
        """Follow one frame's ankle world positions ``(P, 2, 3)`` (the stream's own, not moved);
        returns the offsets ``(P,)``."""
        with np.errstate(invalid="ignore"):  # NaN speed on a first frame: not still
            still = rot.norm(ankles - self._last) * self._fps < self.speed
        self._last = ankles
        planted = still.any(axis=-1)
        height = np.where(still, ankles[..., 1], np.inf).min(axis=-1) - self.ankle_height
        error = np.where(planted, height, self.offset) - self.offset
        self.offset = self.offset + np.where(error < 0.0, self._down, self._up) * error
        return self.offset
