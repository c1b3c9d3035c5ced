"""Causal foot locking: feet that touch the ground stay where they landed, by two-bone leg IK.

A stylizer changes the legs and the root's speed independently, so a planted foot of the output
tends to slide. This is the animator's fix, done one frame at a time (no lookahead), after any
stylizer: a foot is in contact while the *input*'s ankle is low and slow (real capture knows when
a foot is planted; the stylized output, sliding, does not), and the output's ankle is held: on
the frame contact starts, its position is recorded (the ankle glides on with the stylizer's motion
for a few frames, less each frame, so that it comes to rest without a jolt); while it lasts, hip and
knee are turned (two-bone IK, knee bending in its own plane) so that the ankle stays there, and the
foot keeps the heading it landed with (toes do not pivot about the planted ankle) and the pitch and
roll the stylizer gives it (its heel-toe roll). Where the stylizer's own ankle moves more than
``max_stretch`` away, the held one is dragged after it on that leash: a style that walks on while
the performer stands slides the foot only that far behind, rather than letting go and snapping the
leg back. When contact ends, the correction fades out over ``release_seconds``. Only the local
rotations of the upper leg, lower leg and foot change, and every other joint is untouched.

With ``anchor_root`` (the default), the root is held back where a style runs faster than its legs:
once a held ankle's stylized one has run more than ``anchor_stretch`` further since landing than
the input's ankle has, while the stylized foot is down too (its ankle low: not a foot of another
footfall, swinging), the root moves back along its step of that frame, at most the whole step
(held back, never pushed backwards). The output then covers the ground its stance legs cover, as
a walk does; with the leash alone, an "active" style ran an unseen walk at twice its speed and
dragged the planted feet at 1.3 m/s.

With ``clearance`` (the default), a foot the input lifts is also lifted in the output: the output's
ankle is never lower than the input's, so a stylized foot cannot skim the floor while the
performer's is in the air. On recordings the stylizers never saw (CMU walks), outputs otherwise
brought their feet down early and slid them in at walking speed.
"""

from __future__ import annotations

import numpy as np

from motion_style_ros.core import rotations as rot
from motion_style_ros.core.easing import smoothstep
from motion_style_ros.core.features import CONTACT_HEIGHT, Mask, wrap_angle
from motion_style_ros.core.motion import forward_kinematics, rest_positions
from motion_style_ros.core.skeleton import Skeleton, canonical

LEGS = (("UpperLeg_L", "LowerLeg_L", "Foot_L"), ("UpperLeg_R", "LowerLeg_R", "Foot_R"))
TOES = ("Toes_L", "Toes_R")
_EPS = 1e-9
GLIDE = 0.5  # a new lock follows this much of the stylizer's ankle motion, then its square, ...
_NEAR = 1e-6  # m: a goal this close to the ankle leaves the leg as it is
ANCHOR_EASE = 0.3  # the fraction of the way to the wanted hold-back the root goes each frame
DOWN = 0.08  # m: a stylized ankle this far above the contact height is still down (on its toes)
PLANTED_SPEED = 0.3  # m/s: an ankle below its contact height and slower than this is planted
_SIDES = np.tile([0, 1], 3)  # the leg (left, right) of each joint of the chain: hips, knees, ankles


class FootLock:
    """Foot locking for ``performers`` streamed performers at ``fps`` (see the module docstring).

    An input ankle is planted below its features contact height and slower than ``speed`` (m/s;
    stricter than the features' contact speed, which also counts the heel-off roll, when the
    ankle itself moves).
    """

    def __init__(self, performers: int, fps: float, skeleton: Skeleton | None = None,
                 release_seconds: float = 0.4, max_stretch: float = 0.1,
                 speed: float = PLANTED_SPEED, clearance: bool = True, anchor_root: bool = True,
                 anchor_stretch: float = 0.02) -> None:
        self.skeleton = sk = skeleton or canonical()
        self.fps = float(fps)
        self._hip, self._knee, self._ankle = (np.array([sk.index(leg[k]) for leg in LEGS]) for k in range(3))
        # the joints whose world rotations the IK needs: the hips' parents, then hip, knee, ankle
        self._legs = [int(j) for joints in ([sk.parents[j] for j in self._hip], self._hip, self._knee,
                                            self._ankle) for j in joints]
        self._chain = np.concatenate([self._hip, self._knee, self._ankle])
        self._height = np.array([CONTACT_HEIGHT[sk.names[j]] for j in self._ankle])
        self._toes = sk.offsets[[sk.index(n) for n in TOES]]  # the feet's forward vectors
        self._fade = 1.0 / max(release_seconds * self.fps, 1.0)  # weight lost per frame
        self.max_stretch = max_stretch
        self.speed = speed
        self.clearance = clearance
        self.anchor_root = anchor_root
        self.anchor_stretch = anchor_stretch
        self._last_root = np.full((performers, 3), np.nan)  # the output's root of the last frame
        self._back = np.zeros(performers)  # how far the root is held back this frame (m)
        self._last = np.full((performers, 2, 3), np.nan)  # input ankle positions of the last frame
        self._last_out = np.full((performers, 2, 3), np.nan)  # and the stylizer's
        self._target = np.zeros((performers, 2, 3))  # where a locked ankle stays
        self._landed = np.zeros((performers, 2, 3))  # where the input's ankle was when it landed
        self._offset = np.zeros((performers, 2, 3))  # target - ankle when the lock was released
        self._heading = np.zeros((performers, 2))  # a locked foot's heading (rad about +Y)
        self._turn = np.zeros((performers, 2))  # its heading - the stylizer's when released
        self._glide = np.zeros((performers, 2))  # how much of the stylizer's motion a lock follows
        self._weight = np.zeros((performers, 2))  # 1 locked, fading to 0 after contact
        self._locked = np.zeros((performers, 2), dtype=bool)
        self._axis = np.zeros((performers, 2, 3))  # last good knee axis, for a straight leg
        self._own = OwnContact(performers, self.fps, speed)  # contacts of a stream with no input

    def reset(self, which: Mask = None) -> None:
        """These performers' next frame starts afresh (no lock carried over a jump)."""
        which = slice(None) if which is None else which
        self._last[which] = np.nan
        self._last_out[which] = np.nan
        self._last_root[which] = np.nan
        self._back[which] = 0.0
        self._weight[which] = 0.0
        self._locked[which] = False
        self._own.reset(which)

    @property
    def ankles(self) -> np.ndarray:
        """Indices of the ankle (foot) joints, left then right: pass the input's positions of these."""
        return self._ankle

    def __call__(self, rotations: np.ndarray, root_positions: np.ndarray,
                 input_ankles: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The output frame with the legs of planted feet locked: local rotations ``(P, J, 4)``
        and root positions ``(P, 3)`` (new arrays; the root moves only by ``anchor_root``);
        ``input_ankles`` ``(P, 2, 3)``: world positions of the input's ankles (:attr:`ankles`) in
        the frame the output was made from; None for a stream with no input (a generated one),
        whose own low, slow ankles are taken as planted (:class:`OwnContact`)."""
        sk = self.skeleton
        g_rot, g_pos = forward_kinematics(sk, rotations, rest_positions(sk, root_positions), self._legs)
        hip, knee, ankle = g_pos[:, self._hip], g_pos[:, self._knee], g_pos[:, self._ankle]
        if input_ankles is None:
            input_ankles = self._own(ankle)
        speed = rot.norm(input_ankles - self._last) * self.fps  # NaN on a first frame
        self._last = input_ankles.copy()  # reset() writes into it: never into the caller's array
        contact = (input_ankles[..., 1] < self._height) & (speed < self.speed)

        step = ankle - self._last_out  # NaN on a first frame
        self._last_out = ankle
        start = contact & ~self._locked
        # A new lock lets the ankle glide on with the stylizer's motion, less each frame, so that it
        # comes to rest without a jolt.
        glide = self._locked & contact
        self._target += np.where(glide[..., None], self._glide[..., None] * step, 0.0)  # finite where gliding
        self._glide = np.where(start, GLIDE, self._glide * GLIDE)
        np.copyto(self._target, ankle, where=start[..., None])
        np.copyto(self._landed, input_ankles, where=start[..., None])
        parent, g_upper, g_lower, g_foot = (g_rot[:, 2 * k:2 * k + 2] for k in range(4))
        toes = rot.rotate(g_foot, self._toes)
        heading = np.arctan2(toes[..., 0], toes[..., 2])
        np.copyto(self._heading, heading, where=start)
        held_turn = wrap_angle(self._heading - heading)  # a held foot's heading against the stylizer's
        # the leash: a held ankle at most max_stretch from the stylizer's
        away = ankle - self._target
        reach = rot.norm(away, keepdims=True)
        root = np.array(root_positions, dtype=np.float64)
        if self.anchor_root:
            shift = self._anchor(away - (input_ankles - self._landed), ankle, root)
            root += shift
            hip, knee, ankle = hip + shift[:, None], knee + shift[:, None], ankle + shift[:, None]
            away = away + shift[:, None]
            reach = rot.norm(away, keepdims=True)
        self._last_root = root
        self._target += np.where(self._locked[..., None] & (reach > self.max_stretch),
                                 away * (1.0 - self.max_stretch / np.maximum(reach, _EPS)), 0.0)
        released = self._locked & ~contact
        np.copyto(self._offset, self._target - ankle, where=released[..., None])
        np.copyto(self._turn, held_turn, where=released)
        self._locked = contact
        self._weight = np.where(contact, 1.0, np.maximum(self._weight - self._fade, 0.0))
        # Locked: the ankle stays at its target. Released: the correction it had then fades out,
        # so the leg eases back onto the stylizer's swing rather than being held behind. Not
        # locked: no lower than the input's ankle.
        fade = smoothstep(self._weight)
        goal = np.where(contact[..., None], self._target, ankle + fade[..., None] * self._offset)
        if self.clearance:
            goal[..., 1] = np.where(contact, goal[..., 1], np.maximum(goal[..., 1], input_ankles[..., 1]))
        turn = np.where(contact, held_turn, fade * self._turn)
        moved = (rot.norm(goal - ankle) > _NEAR) | (np.abs(turn) > _NEAR)
        if not moved.any():
            return rotations.copy(), root
        g_upper, g_lower = self._two_bone(g_upper, g_lower, hip, knee, ankle, goal)
        g_foot = rot.multiply(rot.from_yaw(turn), g_foot)
        # local = parent's world^-1 * world, for upper leg, lower leg and foot in one call
        local = rot.multiply(rot.conjugate(np.concatenate([parent, g_upper, g_lower], axis=1)),
                             np.concatenate([g_upper, g_lower, g_foot], axis=1))
        out = rotations.copy()
        out[:, self._chain] = np.where(moved[:, _SIDES, None], local, out[:, self._chain])
        return out, root

    def _anchor(self, ahead: np.ndarray, ankle: np.ndarray, root: np.ndarray) -> np.ndarray:
        """``(P, 3)``: how far to move each root back along its own step of this frame (at most
        the whole step) so that no held ankle whose stylized foot is down has run more than
        ``anchor_stretch`` further since it landed than the input's ankle (``ahead``, ``(P, 2, 3)``)."""
        reach = rot.norm(ahead, keepdims=True)
        down = self._locked & (reach[..., 0] > self.anchor_stretch) & (ankle[..., 1] < self._height + DOWN)
        step = root - self._last_root
        step[np.isnan(step)] = 0.0  # NaN on a first frame: no step to hold back
        step[:, 1] = 0.0
        length = rot.norm(step, keepdims=True)
        forward = step / np.maximum(length, _EPS)
        beyond = ahead * (1.0 - self.anchor_stretch / np.maximum(reach, _EPS))
        excess = np.add.reduce(beyond * forward[:, None], axis=-1)  # how far along the step
        want = np.where(down, excess, 0.0).max(axis=1, initial=0.0)
        # eased in and out, so the root's speed changes smoothly (the IK holds the foot meanwhile)
        self._back = np.minimum(self._back + ANCHOR_EASE * (want - self._back), length[:, 0])
        return -forward * self._back[:, None]

    def _two_bone(self, g_upper, g_lower, hip, knee, ankle, goal):
        """World rotations of upper and lower leg that put the ankle at ``goal`` (as near as the
        leg reaches): bend the knee to the goal's distance, then swing the hip onto it."""
        u, v = hip - knee, ankle - knee
        a, b = rot.norm(u), rot.norm(v)
        axis = rot.cross(u, v)
        size = rot.norm(axis, keepdims=True)
        good = size[..., 0] > 1e-6 * a * b
        self._axis[good] = (axis / np.maximum(size, _EPS))[good]
        axis = self._axis  # zero until the leg was first seen bent: then the knee is left alone
        known = (axis != 0.0).any(axis=-1)
        c = np.minimum(np.maximum(rot.norm(goal - hip), np.abs(a - b) + 1e-4), a + b - 1e-4)
        now = np.arccos(_unit_clip(np.add.reduce(u * v, axis=-1) / np.maximum(a * b, _EPS)))
        wanted = np.arccos(_unit_clip((a * a + b * b - c * c) / np.maximum(2 * a * b, _EPS)))
        bend = rot.from_axis_angle(axis, np.where(known, wanted - now, 0.0))
        ankle = knee + rot.rotate(bend, v)
        swing = rot.between(ankle - hip, goal - hip)
        return rot.multiply(swing, g_upper), rot.multiply(swing, rot.multiply(bend, g_lower))


class OwnContact:
    """Input ankles for :class:`FootLock` on a stream that has no input (a generated one): an
    ankle of the stream itself below its contact height and slower than ``speed`` (m/s,
    horizontal; a foot that slides faster is taken for a low step) is planted where it came down,
    and that position is what the lock is given as the input's ankle; any other ankle is given as
    it is. The lock then holds planted feet still and, where the stream's root runs ahead of them,
    holds the root back."""

    def __init__(self, performers: int, fps: float, speed: float = PLANTED_SPEED) -> None:
        self._height = np.array([CONTACT_HEIGHT[leg[2]] for leg in LEGS])
        self._fps, self.speed = float(fps), speed
        self._last = np.full((performers, 2, 3), np.nan)  # the ankles of the last frame
        self._landed = np.full((performers, 2, 3), np.nan)  # where a planted ankle came down

    def reset(self, which: Mask = None) -> None:
        """These performers' next frame starts afresh (no planted foot carried over a jump)."""
        which = slice(None) if which is None else which
        self._last[which] = np.nan
        self._landed[which] = np.nan

    def __call__(self, ankles: np.ndarray) -> np.ndarray:
        """``(P, 2, 3)``: the lock's input ankles for this frame's own ankles ``(P, 2, 3)``."""
        step = ankles - self._last
        speed = np.hypot(step[..., 0], step[..., 2]) * self._fps  # NaN on the first frame
        down = (ankles[..., 1] < self._height) & ~(speed >= self.speed)
        self._last = ankles.copy()  # reset() writes into it: never into the caller's array
        self._landed = np.where((down & np.isnan(self._landed[..., 0]))[..., None], ankles, self._landed)
        self._landed[~down] = np.nan
        return np.where(down[..., None], self._landed, ankles)


def _unit_clip(x: np.ndarray) -> np.ndarray:
    """``x`` clipped to [-1, 1] (np.clip costs twice as much on one frame's few numbers)."""
    return np.minimum(np.maximum(x, -1.0), 1.0)
