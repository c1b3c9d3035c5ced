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
joint, on the frames where the arm hangs) are found together by dynamic programming over a grid
of angles, from the rotation matrices' moments (:class:`RollModel`), so that a live stream
(:class:`StreamRolls`) needs no frames kept. A chain is rolled only as far as that clearly beats
not rolling it: a rig with the training data's conventions is left alone.

Rigs also disagree on how high the ankle joint sits above the sole: retargeted CMU ankles rest
about 6 cm lower than Bandai's, so the canonical feet sink into the floor and a stylizer takes the
walk for shuffling. :func:`ground` moves the whole clip up or down so that its planted ankles rest
at the training data's height; :class:`StreamGround` does the same causally for a live stream.
"""

from __future__ import annotations

import functools

import numpy as np
from numba import njit

from motion_style_ros.core import jit, roll_kernels
from motion_style_ros.core import rotations as rot
from motion_style_ros.core.jit import norm3
from motion_style_ros.core.motion import Motion
from motion_style_ros.core.proportions import stance_sums
from motion_style_ros.core.skeleton import Skeleton
from motion_style_ros.errors import MotionStyleError

CHAINS = tuple(tuple(f"{j}_{side}" for j in ("Shoulder", "UpperArm", "LowerArm", "Hand"))
               for side in "LR")
STD_FLOOR = 0.05  # 6D components that hardly vary in the training data still allow this much


ANKLES = ("Foot_L", "Foot_R")
PLANTED_PERCENTILE = 5.0  # a clip's planted-ankle height: this percentile of its ankle heights
HANG_DEGREES = 45.0  # an arm hangs while its upper arm is this close to straight down
_HANG_COS = float(np.cos(np.radians(HANG_DEGREES)))


def statistics(motions: list[Motion]) -> dict[str, np.ndarray]:
    """Per-joint mean and standard deviation of the 6D local rotations ``(J, 6)`` over clips (an
    arm chain's joints over the frames where that arm hangs, :func:`arms_hang`), the median
    planted-ankle height (m), and the median performer scale of the clips with steps in them
    (:mod:`motion_style_ros.core.proportions` measures streams against it)."""
    sk = motions[0].skeleton
    d6 = np.concatenate([rot.to_6d(m.rotations) for m in motions])
    hang = np.concatenate([arms_hang(m.global_positions(), sk) for m in motions])
    use = np.ones(d6.shape[:2], dtype=bool)
    for side, chain in enumerate(CHAINS):
        use[:, [sk.index(n) for n in chain]] = hang[:, side, None]
    count = use.sum(axis=0)[:, None]
    mean = np.where(use[..., None], d6, 0.0).sum(axis=0) / count
    var = np.where(use[..., None], np.square(d6 - mean), 0.0).sum(axis=0) / count
    sums = np.array([stance_sums(m) for m in motions])
    steps = sums[:, 1] > 50.0  # clips with steps in them: the others keep the prior's 1
    return {"names": np.array(sk.names), "mean": mean, "std": np.maximum(np.sqrt(var), STD_FLOOR),
            "ankle_height": np.median([planted_ankle_height(m) for m in motions]),
            "scale_reference": float(np.median(sums[steps, 0] / sums[steps, 1]))}


def arms_hang(positions: np.ndarray, skeleton: Skeleton) -> np.ndarray:
    """``(..., 2)``: whether each arm (left, right) hangs, its upper arm within :data:`HANG_DEGREES`
    of straight down, from global joint positions ``(..., J, 3)``. Rolls are estimated on these
    frames only: how a raised or waving arm's frames turn says more about the motion than the rig."""
    upper, lower = _arm_bones(skeleton)
    bone = positions[..., lower, :] - positions[..., upper, :]
    return -bone[..., 1] > _HANG_COS * np.maximum(rot.norm(bone), 1e-9)


@functools.cache
def _arm_bones(skeleton: Skeleton) -> tuple[np.ndarray, np.ndarray]:
    """The upper and lower arm joints (left, right), looked up once per skeleton."""
    return tuple(np.array([skeleton.index(f"{j}_{s}") for s in "LR"], dtype=np.int64) for j in ("UpperArm", "LowerArm"))


def planted_ankle_height(motion: Motion) -> float:
    """How high the ankles are when the feet are on the floor: a low percentile of their heights."""
    ankles = [motion.skeleton.index(n) for n in ANKLES]
    return float(np.percentile(motion.global_positions()[:, ankles, 1], PLANTED_PERCENTILE))


def ground(motion: Motion, stats: dict[str, np.ndarray]) -> Motion:
    """``motion`` moved vertically so that its planted ankles rest at ``stats["ankle_height"]``."""
    positions = motion.positions.copy()
    positions[:, motion.skeleton.pelvis, 1] += float(stats["ankle_height"]) - planted_ankle_height(motion)
    return Motion(motion.skeleton, motion.rotations, positions, motion.fps)


ARM_JOINTS = tuple(name for chain in CHAINS for name in chain)
ROLL_STEPS = 72  # the grid of roll angles, 5 degrees apart
# How much more typical (mean squared z-score per frame, per chain) the rolled frames must be than
# the unrolled ones before a chain is rolled at all, and fully: Bandai test takes reach 20 at most,
# Xia's 37 (their rolls are small, and partly rolling them early in a stream made it unstable),
# retargeted CMU arms 57 and up, on any number of frames from 4 to a whole clip.
ROLL_EVIDENCE = (40.0, 55.0)
# Joints whose own frame is never rolled (their parent's roll is still undone on their left; their
# own is solved for with the chain, so that it does not bend the others', and then dropped): how a
# hand's frame turns says more about what it holds and does than about the rig, and a live estimate
# of it drifted with the motion for seconds (swordplay, punches) while the whole clip's did not.
UNROLLED = ("Hand_L", "Hand_R")
RESTART_DEGREES = 10.0  # first measured rolls this far off: applied at once, the stylizer's memory reset
_RESTART = float(np.radians(RESTART_DEGREES))
ROLL_MIN_FRAMES = 1  # hanging-arm frames a chain needs before its rolls are estimated
# With fewer hanging-arm frames than this, a chain is rolled only on evidence above the ramp's top
# (all or nothing): a Xia jump's first 3 frames reached its middle (25 deg, undone 3 frames later).
ROLL_SURE_FRAMES = 6
_D6 = [0, 3, 6, 1, 4, 7]  # the 6D components among a row-major 3x3 matrix's entries


class RollModel:
    """The training statistics as quadratic forms in a joint's rotation matrix.

    A 6D rotation is linear in the matrix, so the summed squared z-score of a joint's frames rolled
    by any pair of grid angles (its parent's frame by ``a``, its own by ``b``) follows from the
    frames' first and second moments alone: a live stream keeps 90 numbers per arm joint, and a
    clip of any length costs one pass. Built once per process (:func:`roll_model`).
    """

    def __init__(self, stats: dict[str, np.ndarray], steps: int = ROLL_STEPS) -> None:
        names = list(stats["names"])
        joints = [names.index(n) for n in ARM_JOINTS]
        self.angles = np.arange(steps) * (2 * np.pi / steps)
        c, s = np.cos(self.angles), np.sin(self.angles)
        rolls = np.zeros((steps, 3, 3))
        rolls[:, 0, 0] = 1.0
        rolls[:, 1, 1], rolls[:, 1, 2], rolls[:, 2, 1], rolls[:, 2, 2] = c, -s, s, c
        basis = np.eye(9).reshape(9, 3, 3)
        # 6D of R_a^T E_k R_b for the 9 basis matrices E_k: (A, B, 6, 9)
        rolled = np.einsum("aji,kjl,blm->abkim", rolls, basis, rolls).reshape(steps, steps, 9, 9)
        linear = rolled[..., _D6].swapaxes(-1, -2)
        mean, std = stats["mean"][joints], stats["std"][joints]  # (8, 6)
        g = linear[None] / std[:, None, None, :, None]  # (8, A, B, 6, 9)
        centre = mean / std
        quadratic = np.einsum("jabki,jabkl->jabil", g, g).reshape(len(joints), steps, steps, 81)
        linear = np.einsum("jabki,jk->jabi", g, centre)
        # A cost is of degree 2 in (cos, sin) of each angle: on the grid it is exactly
        # basis @ coefficients @ basis.T with 5 x 5 coefficients linear in the moments. Solving
        # from those reads 8 x 25 x 90 numbers instead of the grid's 8 x 72 x 72 x 90 (27 MB per
        # solve, 1.4 ms, every 3rd model frame of a stream's first 2 s).
        self.basis = np.stack([np.ones(steps), c, s, np.cos(2 * self.angles), np.sin(2 * self.angles)], axis=1)
        project = np.linalg.pinv(self.basis)  # (5, A): the columns are orthogonal on the grid
        tables = np.concatenate([quadratic, -2.0 * linear], axis=-1).transpose(0, 3, 1, 2)  # (8, 90, A, B)
        self.coefficients = np.ascontiguousarray(
            (project @ tables @ project.T).reshape(len(joints), 90, 25).swapaxes(1, 2))
        self.constant = np.square(centre).sum(axis=-1)
        self._unrolled = np.array([name in UNROLLED for name in ARM_JOINTS])

    def solve(self, second: np.ndarray, first: np.ndarray, count: np.ndarray) -> np.ndarray:
        """``(P, 8)``: the rolls (radians, :data:`ARM_JOINTS` order) that make the frames most
        typical, from the moments ``second`` ``(P, 8, 9, 9)``, ``first`` ``(P, 8, 9)`` and frame
        counts ``(P, 8)``: chosen together along each chain by dynamic programming (its first
        parent, the chest, keeps its frame), each joint's refined between grid points by a
        parabola through its chain's cost (its neighbours' rolls held), so that a live estimate and
        a whole clip's differ by less than a grid step, and each chain's scaled by how clearly it
        beats no rolls at all (:data:`ROLL_EVIDENCE`; :func:`~motion_style_ros.core.roll_kernels.solve_rolls`)."""
        low, high = ROLL_EVIDENCE
        return roll_kernels.solve_rolls(self.coefficients, self.basis, self.constant, self.angles,
                                   jit.rows(second), jit.rows(first), jit.rows(count),
                                   len(CHAINS[0]), ROLL_SURE_FRAMES, low, high, ROLL_MIN_FRAMES,
                                   self._unrolled)


_MODELS: dict[bytes, RollModel] = {}


def roll_model(stats: dict[str, np.ndarray]) -> RollModel:
    """The :class:`RollModel` of these statistics, built once."""
    key = np.asarray(stats["mean"]).tobytes() + np.asarray(stats["std"]).tobytes()
    if key not in _MODELS:
        _MODELS[key] = RollModel(stats)
    return _MODELS[key]


def arm_moments(rotations: np.ndarray, hang: np.ndarray, joints: list[int]
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Second ``(..., 8, 9, 9)`` and first ``(..., 8, 9)`` moments of the arm joints' rotation
    matrices and the frame counts ``(..., 8)``, summed over the frames ``(T, ..., J, 4)`` where
    each joint's arm hangs (``hang`` ``(T, ..., 2)``)."""
    q = rotations[..., joints, :]
    v = rot.to_matrix(q).reshape(q.shape[:-1] + (9,))  # (T, ..., 8, 9)
    w = np.repeat(hang, len(CHAINS[0]), axis=-1).astype(np.float64)  # (T, ..., 8)
    # sums over time as matrix products (transpose: np.moveaxis costs more than the sums on a frame)
    last = v.ndim - 1
    weighted = (w[..., None] * v).transpose(*range(1, v.ndim), 0)  # (..., 8, 9, T)
    return (weighted @ v.transpose(*range(1, last), 0, last), np.add.reduce(weighted, axis=-1),
            w.sum(axis=0))


def apply_rolls(rotations: np.ndarray, joints: list[int], angles: np.ndarray, undo: bool = False
                ) -> np.ndarray:
    """``rotations`` ``(..., J, 4)`` with the arm joints' frames rolled by ``angles`` ``(..., 8)``
    (each joint's local rotation turned by its parent's inverse roll on the left and its own on
    the right; positions do not move). ``undo`` turns conformed rotations back."""
    lead, n_joints = rotations.shape[:-2], rotations.shape[-2]
    out = roll_kernels.roll_rows(jit.rows(rotations).reshape(-1, n_joints, 4),
                            np.asarray(joints, dtype=np.int64),
                            jit.rows(np.broadcast_to(angles, lead + (len(joints),))).reshape(-1, len(joints)),
                            len(CHAINS[0]), undo)
    return out.reshape(rotations.shape)


def clip_rolls(motion: Motion, stats: dict[str, np.ndarray]) -> np.ndarray:
    """``(8,)``: the rolls (radians, :data:`ARM_JOINTS` order) that conform a whole clip."""
    sk = motion.skeleton
    if list(stats["names"]) != list(sk.names):
        raise MotionStyleError("rotation statistics are for another skeleton")
    joints = [sk.index(n) for n in ARM_JOINTS]
    moments = arm_moments(motion.rotations, arms_hang(motion.global_positions(), sk), joints)
    return roll_model(stats).solve(*(m[None] for m in moments))[0]


def conform_rolls(motion: Motion, stats: dict[str, np.ndarray]) -> Motion:
    """``motion`` with constant per-joint rolls about the bone axes (see the module docstring),
    chosen on its frames where the arms hang; global positions are unchanged to rounding."""
    joints = [motion.skeleton.index(n) for n in ARM_JOINTS]
    rotations = apply_rolls(motion.rotations, joints, clip_rolls(motion, stats))
    return Motion(motion.skeleton, rotations, motion.positions, motion.fps)


class StreamRolls:
    """:func:`conform_rolls` for ``performers`` live streams, from each stream itself.

    Each model frame adds its hanging arms' rotations to the performer's moments; the rolls are
    solved on every frame until they are first found (and then applied at once: :meth:`observe`),
    then every ``solve_seconds`` for the first ``settle_seconds`` of a stream and every second
    after, and the applied rolls ease towards later solutions with time constant
    ``ease_seconds`` (they never jump the stylizer's input). A stream's rolls are its rig's, so they hold for as long as the performer streams: :meth:`clear` starts a performer's
    calibration afresh; :meth:`calibrate` sets it from a whole clip at once (the offline path) and
    keeps it.
    """

    def __init__(self, performers: int, fps: float, stats: dict[str, np.ndarray], skeleton: Skeleton,
                 solve_seconds: float = 0.1, settle_seconds: float = 2.0, ease_seconds: float = 0.1
                 ) -> None:
        self.stats = stats
        self.model = roll_model(stats)
        self.skeleton = skeleton
        self.joints = [skeleton.index(n) for n in ARM_JOINTS]
        self._joints = np.array(self.joints, dtype=np.int64)
        self._every = max(1, round(solve_seconds * fps))
        self.settle_frames = self._settle = round(settle_seconds * fps)
        self._late = max(1, round(fps))
        self._gain = 1.0 - np.exp(-1.0 / (fps * ease_seconds))
        n = len(self.joints)
        self._second = np.zeros((performers, n, 9, 9))
        self._first = np.zeros((performers, n, 9))
        self._count = np.zeros((performers, n))
        self.frames = np.zeros(performers, dtype=np.int64)  # model frames seen
        self.target = np.zeros((performers, n))
        self.angles = np.zeros((performers, n))
        self.frozen = np.zeros(performers, dtype=bool)
        self._restarted = np.zeros(performers, dtype=bool)

    def clear(self, which: np.ndarray | slice) -> None:
        """These performers' calibration starts again from nothing (no rolls)."""
        for a in (self._second, self._first, self._count, self.frames, self.target, self.angles):
            a[which] = 0
        self.frozen[which] = self._restarted[which] = False

    def calibrate(self, performer: int, motion: Motion) -> None:
        """One performer's rolls from a whole clip, applied at once and kept."""
        self.target[performer] = self.angles[performer] = clip_rolls(motion, self.stats)
        self.frozen[performer] = True

    def conform(self, rotations: np.ndarray) -> np.ndarray:
        """A frame's rotations ``(P, J, 4)`` with each performer's rolls as they stand (as they
        are, for a rig that needs none: the per-frame path costs nothing then)."""
        return apply_rolls(rotations, self.joints, self.angles) if self.angles.any() else rotations

    def observe(self, rotations: np.ndarray, positions: np.ndarray) -> np.ndarray:
        """Add one model frame ``(P, J, 4)`` (the stream's own rotations) with its global joint
        positions ``(P, J, 3)`` (which the rolls do not change), and move the rolls on. Returns
        the performers whose rig has just been measured within their first seconds, its rolls
        :data:`RESTART_DEGREES` or more from the ones applied until then: they are applied at once,
        and a stylizer with a memory can forget the frames before."""
        live = ~self.frozen
        measured = np.zeros(len(live), dtype=bool)
        if not live.any():
            return measured
        upper, lower = _arm_bones(self.skeleton)
        roll_kernels.add_arm_moments(jit.rows(rotations),
                                jit.rows(positions), self._joints, upper, lower,
                                _HANG_COS, live, self._second, self._first, self._count)
        # every frame while the first few hanging-arm frames come in (until the rig is measured),
        # then every solve_seconds, every second after
        due = roll_kernels.rolls_due(live, self.frames, self._count, len(CHAINS[0]), self._restarted, self._settle,
                                self._every, self._late, ROLL_SURE_FRAMES)
        if due.any():
            self.target[due] = self.model.solve(self._second[due], self._first[due], self._count[due])
        measured = roll_kernels.ease_rolls(live, due, self.frames, self._settle, self._restarted, self.target,
                                      self.angles, self._gain, _RESTART)
        return measured

    def hanging_frames(self, performer: int) -> np.ndarray:
        """``(2,)``: the frames each arm (left, right) of a performer has hung in so far."""
        return self._count[performer, ::len(CHAINS[0])].copy()

    def undo(self, rotations: np.ndarray) -> np.ndarray:
        """Conformed rotations ``(P, J, 4)`` turned back to each stream's own joint frames."""
        return apply_rolls(rotations, self.joints, self.angles, undo=True) if self.angles.any() else rotations


class StreamGround:
    """:func:`ground` for ``performers`` live streams at ``fps``: how far each performer's planted
    ankles rest above ``ankle_height`` (the training data's), so that a session can move the stream
    down by that much before the stylizer and its output back up (the user's floor stays theirs).

    A performer's first frame sets its offset from the lower ankle (:meth:`start`: a stream starts
    with a foot on the floor); then it follows the height of the lower of the ankles that stand
    still (slower than ``speed`` m/s): down within ``down_seconds``, up only over ``up_seconds``
    (a still ankle may be rolling up onto the toes; the floor is the low envelope, as the offline
    percentile takes it). For the first ``settle_seconds`` it goes up within ``down_seconds`` too:
    a stream's first frame may be a calibration pose off its floor (a CMU file's T-pose stands 5 cm
    lower than its walk), and a floor taken from it made every stylized step a crouch for seconds.
    """

    def __init__(self, performers: int, fps: float, ankle_height: float, down_seconds: float = 0.2,
                 up_seconds: float = 3.0, speed: float = 0.25, settle_seconds: float = 1.0) -> None:
        self.ankle_height = float(ankle_height)
        self.speed = speed
        self._fps = float(fps)
        self._down, self._up = (1.0 - np.exp(-1.0 / (self._fps * s)) for s in (down_seconds, up_seconds))
        self._settle = settle_seconds * self._fps  # frames
        self._frames = np.zeros(performers)  # since each performer's start
        self._last = np.full((performers, 2, 3), np.nan)
        self.offset = np.zeros(performers)

    def start(self, ankles: np.ndarray, which: np.ndarray) -> None:
        """These performers start afresh with this frame's ankle world positions ``(P, 2, 3)``."""
        self._frames[which] = 0.0
        self.offset[which] = ankles[which, :, 1].min(axis=-1) - self.ankle_height
        self._last[which] = np.nan

    def update(self, ankles: np.ndarray) -> np.ndarray:
        """Follow one frame's ankle world positions ``(P, 2, 3)`` (the stream's own, not moved);
        returns the offsets ``(P,)``."""
        up = np.where(self._frames < self._settle, self._down, self._up)
        self._frames += 1.0
        follow_ground(jit.rows(ankles), self._last, self.offset, self._fps,
                              float(self.speed), self.ankle_height, self._down, up)
        return self.offset


@njit(cache=True)
def follow_ground(ankles, last, offset, fps, speed, height, down, up) -> None:
    """:class:`~motion_style_ros.core.conform.StreamGround`'s frame: each performer's ``offset``
    ``(P,)`` moved towards the height of its lower still ankle (slower than ``speed``; ``ankles``
    ``(P, 2, 3)``, ``last`` the previous frame's, NaN after a start) above ``height``, at rate
    ``down`` when lower and ``up[r]`` when higher; ``last`` becomes ``ankles``."""
    for r in range(ankles.shape[0]):
        lowest = np.inf
        for s in range(2):
            moved = norm3(ankles[r, s, 0] - last[r, s, 0], ankles[r, s, 1] - last[r, s, 1],
                           ankles[r, s, 2] - last[r, s, 2])
            if moved * fps < speed:  # NaN on a first frame: not still
                lowest = min(lowest, ankles[r, s, 1])
            last[r, s] = ankles[r, s]
        if lowest == np.inf:
            continue
        error = (lowest - height) - offset[r]
        offset[r] += (down if error < 0.0 else up[r]) * error
