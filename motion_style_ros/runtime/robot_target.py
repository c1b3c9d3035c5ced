"""A real humanoid robot as the target of (stylized) canonical-skeleton motion.

:class:`RobotTarget` reads a robot's kinematic tree from its URDF (actuated joints with axes,
origins, position and velocity limits; see :mod:`motion_style_ros.io.urdf`), finds which robot
links play the human's thighs, shins, feet, upper arms, forearms, hands and torso, and maps each
frame of canonical motion onto the robot's joint positions and its floating base.

How a frame is mapped
---------------------
* The base (the robot's root link, the pelvis) takes the human pelvis's orientation relative to its
  T-pose (in REP-103 axes: X forward, Z up), and the human pelvis's horizontal position scaled by
  the robot/human leg-length ratio. Its height is an unknown of the solve, pulled towards the
  previous frame's height moved by the human's scaled vertical motion and, weakly, towards the
  human pelvis height scaled by the robot/human standing-height ratio.
* The joints come from one bounded, warm-started least-squares solve per frame: residuals are the
  differences between the robot's link directions and the human's corresponding bone directions
  (torso, shoulder line, thighs, shins, upper arms, forearms and, where the robot has wrists,
  hands: unit vectors in the world, so a robot of other proportions keeps the motion's character),
  each foot's sole normal and heading (flat on the floor, turned as the human foot), the planted
  soles' height above the floor, the soles' penetration of the floor, and small pulls towards the
  previous frame's joints and the zero pose (which hold joints the bones do not determine, e.g. a
  straight arm's twist). The bounds are the joints' position limits.
* A human foot counts as planted while its ankle is within ``PLANTED_HEIGHT`` of its planted-ankle
  height and moves slower than ``PLANTED_SPEED`` horizontally; each foot's height starts where the
  package grounds motion (``ANKLE_HEIGHT``) and follows that ankle at a bounded rate, at most
  ``FOOT_SPREAD`` above the other foot's.
* A joint whose solved step from the previous frame exceeds its velocity limit times the frame
  interval is counted (``stats["velocity_violations"]``, before clamping); the frame is then solved
  again with the bounds narrowed to what each joint can reach (from the clamped pose, so the other
  joints and the base height make up for the held ones), and the result clamped to both limits once
  more for safety. ``stats["clamped"]`` counts the values held at a velocity bound by that second
  solve, plus any the final clamp moved; ``stats["position_violations"]`` the values outside their
  position limits before clamping (zero by construction of the bounded solve);
  ``stats["at_position_limit"]`` the values the bounds held at a position limit (the human asked
  for more than the joint allows). Finally the base moves vertically so that the planted feet's
  lowest sole points rest on the floor (on average) and no sole point of either foot is under it.

Where the parts live
--------------------
:mod:`~motion_style_ros.runtime.robot_kinematics` holds the robot's actuated tree and its forward
kinematics, :mod:`~motion_style_ros.runtime.robot_body_map` finds which links play which bones
(and reads YAML body maps), :mod:`~motion_style_ros.runtime.robot_solve` is the bounded
least-squares solver, this module sets up and solves each frame, and
:mod:`motion_style_ros.evaluation.robot_target` judges a mapped clip (limits, angles, planted feet).

Limitations: no balance (centre of mass, zero-moment point) and no self-collision check; feet are
held on the floor vertically but not locked horizontally (they slide as much as the scaled human's
do); hands keep their direction, not their full orientation; toe and head joints stay near zero.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from motion_style_ros.core import rotations as rot
from motion_style_ros.core.motion import Motion, forward_kinematics
from motion_style_ros.core.skeleton import canonical
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io.urdf import RobotModel, read
from motion_style_ros.runtime.robot_body_map import BodyMap, build, human_ends, load_map
from motion_style_ros.runtime.robot_kinematics import Kinematics, cross
from motion_style_ros.runtime.robot_solve import solve

# Streaming contact: a foot is planted while its ankle is within PLANTED_HEIGHT of its planted-ankle
# height and slow. Each foot's height starts at ANKLE_HEIGHT (where the package grounds motion: the
# training data's planted ankles, io.resources.rotation_stats()["ankle_height"]) and follows its ankle
# at up to FLOOR_DOWN m/s downwards and FLOOR_UP m/s upwards, at most FOOT_SPREAD above the other
# foot's: a stylized or asymmetric performer may plant one ankle a few centimetres higher than the
# other (an elderly stoop measured 3.3 cm), but a foot held still well above the other is lifted.
ANKLE_HEIGHT = 0.117
FLOOR_DOWN = 0.5
FLOOR_UP = 0.05
FOOT_SPREAD = 0.05
PLANTED_HEIGHT = 0.03
PLANTED_SPEED = 0.4  # m/s horizontal ankle speed below which a low foot is planted (streaming)
GAP_SECONDS = 0.5  # a frame this long after the previous one starts without a velocity limit
# A planted human foot's bone (ankle to toes) points this far below the horizontal (CMU and Xia
# median, -15 to -19 degrees); the stream learns its performer's own over planted frames.
FOOT_PITCH = np.radians(-16.0)
FOOT_PITCH_SECONDS = 2.0
CONTACT_RAMP = 0.05  # s: a foot's contact terms fade in and out over this long (no jumps)
_C = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])  # core (Y up) -> REP-103 (Z up)


@dataclass
class Weights:
    """Residual weights of the per-frame solve (directions are unit vectors; heights metres)."""

    limb: float = 1.0  # thighs, shins, upper arms, forearms
    torso: float = 1.0
    shoulders: float = 0.5  # the line between the shoulders (torso twist)
    hand: float = 0.3
    foot_up_planted: float = 2.0
    foot_up_swing: float = 0.3
    foot_heading: float = 0.5
    planted_height: float = 30.0  # per metre
    penetration: float = 30.0  # per metre below the floor
    previous: float = 0.05  # per radian from the previous frame's joints
    zero: float = 0.02  # per radian from the zero pose
    height_follow: float = 5.0  # per metre from the previous height moved as the human's
    height_prior: float = 0.5  # per metre from the scaled human pelvis height


@dataclass
class Mapping:
    """A clip mapped onto a robot (:meth:`RobotTarget.map_clip`)."""

    names: list[str]
    positions: np.ndarray  # (T, J) joint positions
    base_position: np.ndarray  # (T, 3) REP-103 world
    base_orientation: np.ndarray  # (T, 4) quaternion (w, x, y, z), REP-103 world
    angles: np.ndarray  # (T, S) degrees between each robot link and its human bone
    segments: list[str]
    foot_heights: np.ndarray  # (T, 2) left, right: lowest sole point above the floor (m)
    stats: dict
    seconds: float  # time spent in step()


class RobotTarget:
    """Canonical-skeleton motion on a humanoid robot described by a URDF.

    ``RobotTarget(urdf)`` with ``urdf`` a path (or a :class:`RobotModel`); ``body_map``: a YAML
    path or dict naming the anchors (see :mod:`~motion_style_ros.runtime.robot_body_map`) where
    names do not say them. ``step(rotations, root, t)`` maps one frame (streaming, stateful: warm
    start, velocity limits); ``reset()`` starts a new stream; :attr:`base_pose` is the last frame's
    base; ``map_motion`` maps a whole clip through ``step``.
    """

    def __init__(self, urdf: str | Path | RobotModel, body_map: str | Path | dict | None = None,
                 weights: Weights | None = None, solver: str = "lm", iterations: int = 6,
                 ankle_height: float = ANKLE_HEIGHT) -> None:
        if not isinstance(urdf, RobotModel):
            urdf = read(urdf)
        if solver not in ("lm", "scipy"):
            raise MotionStyleError(f"unknown solver {solver!r}; allowed: lm, scipy")
        if isinstance(body_map, (str, Path)):
            body_map = load_map(body_map)
        self.model = urdf
        self.kin = Kinematics(urdf)
        self.weights = weights or Weights()
        self.solver = solver
        self.ankle_height = float(ankle_height)  # the human's planted ankles, core frame (m)
        self.iterations = iterations
        self.names: list[str] = list(self.kin.names)
        self.lower, self.upper, self.velocity = self.kin.lower, self.kin.upper, self.kin.velocity
        self._neutral = np.clip(np.zeros(self.kin.n), self.lower, self.upper)
        self._eye3 = np.eye(3)
        self._adopt(build(self.kin, self.model, dict(body_map or {}), self.weights))
        self._human_setup()
        self.reset()

    # ------------------------------------------------------------------ the body map
    def _adopt(self, bm: BodyMap) -> None:
        """The body map's points and segments, laid out as the solve's residual rows use them."""
        kin = self.kin
        self._S = bm.S
        self.segments = bm.segments
        self._seg_w = bm.seg_weights
        self._human_segments = bm.human_segments
        self._pt_body = bm.pt_body
        self._pt_local = bm.pt_local
        self._pt_anc = kin.anc[self._pt_body]
        self._feet = bm.feet
        self._foot_bodies = np.array([f["body"] for f in self._feet])
        self._foot_axes = np.array([[f["x"], f["z"]] for f in self._feet])  # (2, 2, 3)
        self._contacts = [np.array(f["contacts"]) for f in self._feet]
        self._height_pts = np.concatenate([[f["sole"]] + list(f["contacts"]) for f in self._feet])
        self._height_counts = np.array([1 + len(f["contacts"]) for f in self._feet])
        self._height_is_sole = np.concatenate([[True] + [False] * len(f["contacts"]) for f in self._feet])
        self.leg_length = bm.leg_length
        self.standing_height = bm.standing_height  # root height above the soles at the zero pose
        self.body_map = bm.report

    def _human_setup(self) -> None:
        from motion_style_ros.core.retarget import tpose

        sk = canonical()
        self._sk = sk
        tp = tpose(sk)
        idx = sk.index
        self._hips = sk.pelvis
        self._hands = [idx("Hand_L"), idx("Hand_R")]
        self._hand_sign = np.sign(sk.offsets[self._hands, 0])
        self._ankles = [idx("Foot_L"), idx("Foot_R")]
        self._toes = [idx("Toes_L"), idx("Toes_R")]
        self._rest_hips = rot.to_matrix(tp.rotations[sk.pelvis])
        self.human_leg_length = tp.leg_length()
        self.human_standing_height = float(tp.positions[sk.pelvis, 1])
        self.scale = self.leg_length / self.human_leg_length
        self.height_scale = self.standing_height / self.human_standing_height
        self._hA, self._hB, self._hand_rows = human_ends(sk, self._human_segments, self._hands)

    # ------------------------------------------------------------------ streaming
    def reset(self) -> None:
        """Start a new stream: no previous frame, no velocity limit on the next one."""
        self._q = None
        self._z = None
        self._t = None
        self._h_prev = None
        self._ankle_prev = None
        self._floor = np.full(2, self.ankle_height)
        self._contact = np.zeros(2)
        self._foot_pitch = np.full(2, FOOT_PITCH)
        self.base_pose = (np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0]))
        self.stats = {"frames": 0, "position_violations": 0, "velocity_violations": 0,
                      "clamped": 0, "at_position_limit": 0}
        self.last: dict = {}

    def _human(self, rotations: np.ndarray, root: np.ndarray):
        sk = self._sk
        pos = np.broadcast_to(sk.offsets, (sk.n_joints, 3)).copy()
        pos[self._hips] = root
        g_rot, g_pos = forward_kinematics(sk, rotations[None], pos[None],
                                          joints=[self._hips] + self._hands)
        return rot.to_matrix(g_rot[0]), g_pos[0]

    def step(self, rotations: np.ndarray, root: np.ndarray, t: float) -> np.ndarray:
        """Joint positions ``(J,)`` (URDF order, radians) for one frame: local rotations ``(22, 4)``
        of the canonical skeleton and the pelvis position ``(3,)`` in the core frame (Y up, metres)
        at time ``t`` seconds. :attr:`base_pose` then holds that frame's base."""
        w = self.weights
        rotations, root = self._checked(rotations, root)
        g_rot, g_pos = self._human(rotations, root)
        dt = None if self._t is None else float(t) - self._t
        fresh = dt is None or dt > GAP_SECONDS
        r_base, p_ros, d_h = self._bones(g_rot, g_pos)
        up = r_base[2]  # world Z in the base frame
        planted, contact = self._planted(p_ros, dt, fresh)
        heading, sole_up = self._foot_targets(p_ros, planted, r_base, dt, fresh)
        # Base height target.
        h = float(p_ros[self._hips, 2])
        z_prior = self.height_scale * h
        z_pred = z_prior if fresh else self._z + self.scale * (h - self._h_prev)
        q_prev = self._neutral if self._q is None else self._q
        x0 = np.concatenate([q_prev, [z_pred if self._z is None else self._z]])
        ctx = dict(d_h=d_h, up=up, heading=heading, sole_up=sole_up, contact=contact, q_prev=q_prev,
                   z_pred=z_pred, z_prior=z_prior,
                   w_prev=0.0 if self._q is None else w.previous)
        lo = np.concatenate([self.lower, [0.0]])
        hi = np.concatenate([self.upper, [3.0 * max(self.standing_height, 0.1)]])
        iters = self.iterations if self._q is not None else 10 * self.iterations
        x = self._solve(x0, lo, hi, ctx, iters)
        q, z = self._within_limits(x, lo, hi, ctx, dt, fresh)
        pts, z, foot_h = self._on_the_floor(q, z, up, contact)
        seg = self._S @ pts
        d_r = seg / np.linalg.norm(seg, axis=1, keepdims=True)
        self.last = {"angles": np.degrees(np.arccos(np.clip((d_r * d_h).sum(axis=1), -1.0, 1.0))),
                     "foot_heights": foot_h, "planted": planted,
                     "contact": contact.copy()}
        base_xy = self.scale * p_ros[self._hips, :2]
        self.base_pose = (np.array([base_xy[0], base_xy[1], z]), rot.from_matrix(r_base))
        self._q, self._z, self._t, self._h_prev = q, z, float(t), h
        return q.copy()

    def _checked(self, rotations: np.ndarray, root: np.ndarray):
        """The frame as float64 arrays; a one-line error if it is misshapen or not finite."""
        rotations = np.asarray(rotations, dtype=np.float64)
        root = np.asarray(root, dtype=np.float64)
        if rotations.shape != (self._sk.n_joints, 4) or root.shape != (3,):
            raise MotionStyleError(f"a frame is (22, 4) rotations and a (3,) root, got {rotations.shape} "
                                   f"and {root.shape}")
        if not (np.isfinite(rotations).all() and np.isfinite(root).all()):
            raise MotionStyleError("non-finite values in the frame")
        return rotations, root

    def _bones(self, g_rot: np.ndarray, g_pos: np.ndarray):
        """The base orientation (the human pelvis's turn from its T-pose, in REP-103 axes), the
        human's joint positions in REP-103 axes, and the human bone directions in the base frame."""
        r_base = _C @ (g_rot[0] @ self._rest_hips.T) @ _C.T
        p_ros = g_pos @ _C.T
        v = self._hB @ p_ros - self._hA @ p_ros
        for i, side in self._hand_rows:
            v[i] = _C @ (g_rot[1 + side][:, 0] * self._hand_sign[side])
        d_h = v / np.linalg.norm(v, axis=1, keepdims=True)
        d_h = d_h @ r_base  # R^T d for each row
        return r_base, p_ros, d_h

    def _planted(self, p_ros: np.ndarray, dt: float | None, fresh: bool):
        """Which human feet are planted (low and slow), and each foot's contact weight, ramped."""
        ankles = p_ros[self._ankles]
        heights = ankles[:, 2]
        # Each foot's planted-ankle height follows its ankle, quickly down and slowly up and never by
        # more than a rate (a glitched frame does not move it), within FOOT_SPREAD of the other's.
        if not fresh:
            self._floor += np.clip(heights - self._floor, -FLOOR_DOWN * dt, FLOOR_UP * dt)
            self._floor = np.minimum(self._floor, self._floor.min() + FOOT_SPREAD)
        low = heights < self._floor + PLANTED_HEIGHT
        if fresh or self._ankle_prev is None or dt <= 0:
            planted = low
        else:
            speed = np.linalg.norm((ankles - self._ankle_prev)[:, :2], axis=1) / dt
            planted = low & (speed < PLANTED_SPEED)
        self._ankle_prev = ankles
        if fresh:
            self._contact = planted.astype(np.float64)
        else:
            ramp = max(dt, 0.0) / CONTACT_RAMP
            self._contact = self._contact + np.clip(planted - self._contact, -ramp, ramp)
        return planted, self._contact

    def _foot_targets(self, p_ros: np.ndarray, planted: np.ndarray, r_base: np.ndarray,
                      dt: float | None, fresh: bool):
        """Foot frame targets in the base frame: the human foot's heading, and its pitch relative to
        its planted pitch (flat on the floor when planted, toes down at push-off)."""
        f = p_ros[self._toes] - p_ros[self._ankles]
        flat = np.linalg.norm(f[:, :2], axis=1)
        pitch = np.arctan2(f[:, 2], flat)
        if not fresh:
            self._foot_pitch += planted * (pitch - self._foot_pitch) * min(1.0, dt / FOOT_PITCH_SECONDS)
        hdg = np.where(flat[:, None] > 1e-6, f / np.maximum(flat, 1e-9)[:, None], r_base[:, 0])
        hdg[:, 2] = 0.0
        rel = (pitch - self._foot_pitch)[:, None]
        z_hat = np.array([0.0, 0.0, 1.0])
        heading = (np.cos(rel) * hdg + np.sin(rel) * z_hat) @ r_base
        sole_up = (-np.sin(rel) * hdg + np.cos(rel) * z_hat) @ r_base
        return heading, sole_up

    def _within_limits(self, x: np.ndarray, lo: np.ndarray, hi: np.ndarray, ctx: dict,
                       dt: float | None, fresh: bool):
        """The solved joints ``q`` and base height ``z`` within the limits: violations counted
        before clamping, a second solve inside the velocity box where a joint is too fast, then
        the position limits once more."""
        q_ik, z = x[:-1], float(x[-1])
        eps = 1e-9
        self.stats["frames"] += 1
        self.stats["position_violations"] += int(((q_ik < self.lower - eps) | (q_ik > self.upper + eps)).sum())
        self.stats["at_position_limit"] += int(((q_ik <= self.lower + 1e-6) | (q_ik >= self.upper - 1e-6)).sum())
        q = q_ik.copy()
        if self._q is not None and not fresh:
            reach = self.velocity * max(dt, 0.0)
            step = q - self._q
            fast = np.abs(step) > reach + eps
            if fast.any():
                # Solve again inside the velocity box, from the clamped pose: the other joints and
                # the base height make up for the held ones (a planted foot stays planted).
                self.stats["velocity_violations"] += int(fast.sum())
                vlo = np.concatenate([np.maximum(self.lower, self._q - reach), [lo[-1]]])
                vhi = np.concatenate([np.minimum(self.upper, self._q + reach), [hi[-1]]])
                x = self._solve(np.concatenate([self._q + np.clip(step, -reach, reach), [z]]),
                                vlo, vhi, ctx, self.iterations)
                q, z = x[:-1], float(x[-1])
                q = self._q + np.clip(q - self._q, -reach, reach)
                self.stats["clamped"] += int((np.abs(q - self._q) >= reach - eps).sum())
        safe = np.clip(q, self.lower, self.upper)
        self.stats["clamped"] += int((np.abs(safe - q) > eps).sum())
        return safe, z

    def _on_the_floor(self, q: np.ndarray, z: float, up: np.ndarray, contact: np.ndarray):
        """Planted feet back on the floor after the clamp: their lowest sole points on it (on
        average), and then no sole point of either foot under it, as a real floor holds a robot.
        Returns the mapped points (root frame), the moved base height and the feet's heights."""
        pts, _ = self._points(q)
        foot_h = np.array([float((pts[c] @ up).min()) + z for c in self._contacts])
        weight = min(float(contact.sum()), 1.0)
        shift = float((contact * foot_h).sum() / max(contact.sum(), 1e-9)) if weight else 0.0
        shift = min(shift, float(foot_h.min()))
        z -= weight * shift
        foot_h -= weight * shift
        return pts, z, foot_h

    # ------------------------------------------------------------------ residuals and solve
    def _points(self, q: np.ndarray):
        t = self.kin.fk(q)
        tb = t[self._pt_body]
        pts = (tb[:, :3, :3] @ self._pt_local[:, :, None])[:, :, 0] + tb[:, :3, 3]
        return pts, t

    def _residuals(self, x: np.ndarray, ctx: dict):
        kin, w = self.kin, self.weights
        n = kin.n
        q, z = x[:n], x[n]
        pts, t = self._points(q)
        axes_w = (t[1:, :3, :3] @ kin.axes[:, :, None])[:, :, 0]
        orig = t[1:, :3, 3]
        lever = cross(axes_w[None, :, :], pts[:, None, :] - orig[None, :, :])
        if kin.prismatic.any():
            lever[:, kin.prismatic] = axes_w[kin.prismatic]
        dp = lever * self._pt_anc[:, :, None]  # (P, J, 3)
        # Directions.
        seg = self._S @ pts
        length = np.linalg.norm(seg, axis=1)
        d = seg / length[:, None]
        dseg = (self._S @ dp.reshape(len(pts), -1)).reshape(len(seg), n, 3)
        proj = (self._eye3 - d[:, :, None] * d[:, None, :]) / length[:, None, None]
        dd = proj @ dseg.transpose(0, 2, 1)  # (S, 3, J)
        sw = self._seg_w[:, None]
        blocks_r = [(sw * (d - ctx["d_h"])).ravel()]
        blocks_j = [(sw[:, :, None] * dd).reshape(-1, n)]
        # Foot sole normals and headings.
        contact = ctx["contact"]
        fr = t[self._foot_bodies, :3, :3]  # (2, 3, 3)
        e = self._foot_axes @ fr.transpose(0, 2, 1)  # (2, 2, 3): x, z per foot
        fa = kin.anc[self._foot_bodies]  # (2, J)
        de = cross(axes_w[None, None, :, :], e[:, :, None, :]) * fa[:, None, :, None]  # (2,2,J,3)
        targets = np.stack([ctx["heading"], ctx["sole_up"]], axis=1)
        fw = np.stack([np.full(2, w.foot_heading),
                       w.foot_up_swing + contact * (w.foot_up_planted - w.foot_up_swing)], axis=1)[:, :, None]
        blocks_r.append((fw * (e - targets)).ravel())
        blocks_j.append((fw[..., None] * de.transpose(0, 1, 3, 2)).reshape(-1, n))
        # Heights: the planted soles (weighted by contact) and every sole point below the floor;
        # a fixed number of rows (scipy's solver needs it), zero where inactive.
        up = ctx["up"]
        hp = self._height_pts
        hgt = pts[hp] @ up + z
        dh = dp[hp] @ up  # (H, J)
        wh = np.where(self._height_is_sole, np.repeat(contact, self._height_counts) * w.planted_height,
                      np.where(hgt < 0.0, w.penetration, 0.0))
        rows_r, rows_j, rows_z = wh * hgt, wh[:, None] * dh, wh
        m_dir = sum(len(b) for b in blocks_r)
        r = np.concatenate(blocks_r + [rows_r,
                                       ctx["w_prev"] * (q - ctx["q_prev"]), w.zero * (q - self._neutral),
                                       [w.height_follow * (z - ctx["z_pred"]), w.height_prior * (z - ctx["z_prior"])]])
        jac = np.zeros((len(r), n + 1))
        jac[:m_dir, :n] = np.vstack(blocks_j)
        k = m_dir
        jac[k:k + len(rows_r), :n] = rows_j
        jac[k:k + len(rows_r), n] = rows_z
        k += len(rows_r)
        jac[k:k + n, :n] = ctx["w_prev"] * np.eye(n)
        jac[k + n:k + 2 * n, :n] = w.zero * np.eye(n)
        jac[k + 2 * n, n] = w.height_follow
        jac[k + 2 * n + 1, n] = w.height_prior
        return r, jac

    def _solve(self, x0, lo, hi, ctx, iters):
        return solve(lambda x: self._residuals(x, ctx), x0, lo, hi, iters, self.solver)

    # ------------------------------------------------------------------ offline
    def map_clip(self, motion: Motion) -> Mapping:
        """A canonical-skeleton clip through :meth:`step` (after :meth:`reset`), with the base,
        per-frame link-vs-bone angles and sole heights."""
        if motion.skeleton.names != self._sk.names:
            raise MotionStyleError("a robot target maps canonical-skeleton motion; retarget the clip first")
        g_rot, g_pos = motion.global_transforms()
        rotations = motion.rotations.copy()
        rotations[:, 0] = rot.identity()
        rotations[:, self._hips] = g_rot[:, self._hips]
        root = g_pos[:, self._hips]
        self.reset()
        out = np.empty((motion.n_frames, len(self.names)))
        base_p, base_q = np.empty((motion.n_frames, 3)), np.empty((motion.n_frames, 4))
        angles = np.empty((motion.n_frames, len(self.segments)))
        feet = np.empty((motion.n_frames, 2))
        start = time.perf_counter()
        for i in range(motion.n_frames):
            out[i] = self.step(rotations[i], root[i], i / motion.fps)
            base_p[i], base_q[i] = self.base_pose
            angles[i], feet[i] = self.last["angles"], self.last["foot_heights"]
        seconds = time.perf_counter() - start
        return Mapping(list(self.names), out, base_p, base_q, angles, list(self.segments), feet,
                       dict(self.stats), seconds)

    def map_motion(self, motion: Motion) -> np.ndarray:
        """Joint positions ``(T, J)`` for a canonical-skeleton clip, through :meth:`step`."""
        return self.map_clip(motion).positions

    def link_positions(self, q: np.ndarray, base: tuple[np.ndarray, np.ndarray] | None = None):
        """World positions (REP-103) at joint positions ``q`` and base pose ``(position,
        quaternion)`` of the root link and every link an actuated joint moves, each with its parent
        among them (``None`` for the root), plus the mapped points that end a chain (a forearm
        without a hand link, a hand, the soles): lines for drawing the robot. Returns
        ``(names, positions (N, 3), parents)``."""
        position, quat = base if base is not None else (np.zeros(3), rot.identity())
        r = rot.to_matrix(np.asarray(quat, dtype=np.float64))
        q = np.asarray(q, dtype=np.float64)
        t = self.kin.fk(q)
        names = [self.kin.root] + [j.child for j in self.kin.joints]
        parents = [None] + [names[int(b)] for b in self.kin.body_parent]
        world = list(t[:, :3, 3])
        pts, _ = self._points(q)
        for s, row in zip(self.segments, self._S):
            end = int(np.argmax(row))  # the segment's end point (+1 in its row)
            if s.startswith(("forearm", "hand")):
                names.append(f"{s}_end")
                parents.append(names[int(self._pt_body[end])])
                world.append(pts[end])
        for f, side in zip(self._feet, ("left", "right")):
            for k, c in enumerate(f["contacts"]):
                names.append(f"{side}_sole_{k}")
                parents.append(names[f["body"]])
                world.append(pts[c])
        p = np.array(world) @ r.T + position
        return names, p, parents
