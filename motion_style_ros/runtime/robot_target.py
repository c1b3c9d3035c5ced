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

Why this solver
---------------
The problem is small (one unknown per actuated joint plus the base height, about 120 residuals)
with an analytic Jacobian (each joint's axis crossed with the lever arm), so a projected
Levenberg-Marquardt written here for it (free variables solved, variables at a bound that the
gradient pushes outwards held) converges in 2-4 iterations from the previous frame, at well under
a millisecond of numpy per frame. ``scipy.optimize.least_squares`` (``solver="scipy"``, method
``trf`` with the same bounds, residuals and Jacobian) reaches the same costs but spends several
milliseconds per frame in its own bookkeeping, too much for a 120 Hz node; it stays available as the
reference. An IK library (ikpy, pink/pinocchio) was considered: they solve end-effector pose
targets, whereas what keeps a motion's character on another body is bone *directions* plus feet,
and they would add a dependency (pinocchio is a large compiled one) without saving the Jacobian,
which is a dozen lines here. They would not pay for themselves.

Which links are which
---------------------
From the URDF's names and tree: the knee and elbow joints are the actuated joints whose names
contain ``knee`` / ``elbow`` and ``left``/``l`` or ``right``/``r`` (else the side their origin lies
on at the zero pose, +Y being left). The hip joints are those above a knee that the other knee does
not share, the ankle joints those below it on the way to the lowest link of the leg (the foot); the
shoulder joints are those above an elbow that the other elbow does not share, the waist/torso joints
those both elbows share, the wrist joints those below an elbow. A group of joints acts at the point
nearest all its axes (a hip's centre); a knee or elbow at its joint origin. A forearm without a
wrist ends at the farthest centre of mass below the elbow. The soles are the lowest points of the
foot link's primitive collision shapes. Where names do not say it, a YAML map names the four
anchors (``left_knee``, ``right_knee``, ``left_elbow``, ``right_elbow``: joint names; optionally
``left_foot``, ``right_foot``: link names); anything missing is a one-line
:class:`~motion_style_ros.errors.MotionStyleError`.

Limitations: no balance (centre of mass, zero-moment point) and no self-collision check; feet are
held on the floor vertically but not locked horizontally (they slide as much as the scaled human's
do); hands keep their direction, not their full orientation; toe and head joints stay near zero.
"""

from __future__ import annotations

import time
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from motion_style_ros.core import rotations as rot
from motion_style_ros.core.motion import Motion, forward_kinematics
from motion_style_ros.core.skeleton import canonical
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io import files
from motion_style_ros.io.urdf import RobotModel, read

ACTUATED = ("revolute", "continuous", "prismatic")
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
# Evaluation (offline, whole clips) judges a human foot planted as metrics.foot_skating does:
# ankle within EVAL_CONTACT_HEIGHT of its clip's EVAL_FLOOR_PERCENTILE-th height percentile, and slow.
EVAL_CONTACT_HEIGHT = 0.01
EVAL_FLOOR_PERCENTILE = 5.0
EVAL_SPEED = 0.25
MAP_KEYS = ("left_knee", "right_knee", "left_elbow", "right_elbow", "left_foot", "right_foot")
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


class _Kinematics:
    """The actuated tree as rigid bodies: body 0 is the root link, body k + 1 the child link of
    actuated joint k (URDF order); fixed joints are folded into their parent's body."""

    def __init__(self, model: RobotModel) -> None:
        self.model = model
        src = model.source
        children = defaultdict(list)
        for j in model.joints:
            children[j.parent].append(j)
        child_links = {j.child for j in model.joints}
        roots = [link for link in model.links if link not in child_links]
        if len(roots) != 1:
            raise MotionStyleError(f"{src}: expected one root link, found {len(roots)}: {roots[:4]}")
        root = roots[0]
        # A floating base declared against a 'world' link: the robot starts at that joint's child.
        while len(children[root]) == 1 and (children[root][0].kind in ("floating", "planar")
                                            or (root == "world" and children[root][0].kind == "fixed")):
            root = children[root][0].child
        self.root = root
        actuated = [j for j in model.joints if j.kind in ACTUATED and not j.mimic]
        index = {j.name: k for k, j in enumerate(actuated)}
        n = len(actuated)
        self.link_body: dict[str, int] = {root: 0}
        self.link_T: dict[str, np.ndarray] = {root: np.eye(4)}
        self.link_parent: dict[str, str] = {}
        self.body_parent = np.full(n, -1)
        self.origins = np.zeros((n, 4, 4))
        self.topo: list[int] = []
        stack = [root]
        while stack:
            link = stack.pop()
            for j in reversed(children[link]):
                if j.child in self.link_body:
                    raise MotionStyleError(f"{src}: link {j.child!r} is reached twice (not a tree)")
                self.link_parent[j.child] = link
                if j.name in index:
                    k = index[j.name]
                    self.body_parent[k] = self.link_body[link]
                    self.origins[k] = self.link_T[link] @ j.origin
                    self.link_body[j.child], self.link_T[j.child] = k + 1, np.eye(4)
                    self.topo.append(k)
                elif j.kind in ("fixed",) or j.mimic:
                    self.link_body[j.child] = self.link_body[link]
                    self.link_T[j.child] = self.link_T[link] @ j.origin
                else:
                    raise MotionStyleError(f"{src}: joint {j.name!r} is {j.kind}; only a floating "
                                           f"base and revolute, continuous, prismatic, fixed joints "
                                           f"are supported")
                stack.append(j.child)
        reached = [j for j in actuated if j.child in self.link_body]
        if len(reached) != n or n == 0:
            raise MotionStyleError(f"{src}: no actuated joints below the root link {root!r}")
        self.topo = sorted(self.topo, key=lambda k: self._depth(k))
        self.joints = actuated
        self.names = [j.name for j in actuated]
        self.n = n
        self.axes = np.array([j.axis / np.linalg.norm(j.axis) for j in actuated])
        self.prismatic = np.array([j.kind == "prismatic" for j in actuated])
        self.lower = np.array([j.lower for j in actuated])
        self.upper = np.array([j.upper for j in actuated])
        self.velocity = np.array([j.velocity for j in actuated])
        a = self.axes
        self._aa = a[:, :, None] * a[:, None, :]
        self._k = np.zeros((n, 3, 3))
        self._k[:, 0, 1], self._k[:, 0, 2], self._k[:, 1, 2] = -a[:, 2], a[:, 1], -a[:, 0]
        self._k[:, 1, 0], self._k[:, 2, 0], self._k[:, 2, 1] = a[:, 2], -a[:, 1], a[:, 0]
        # anc[b, k]: joint k moves body b.
        self.anc = np.zeros((n + 1, n))
        for b in range(1, n + 1):
            for k in self.path(b):
                self.anc[b, k] = 1.0
        self._eye3 = np.eye(3)
        self._any_prismatic = bool(self.prismatic.any())
        world = n + 1
        ancestor = np.array([world] + [int(b) for b in self.body_parent] + [world])
        self._doubling = []
        while (ancestor[:-1] != world).any():
            self._doubling.append(ancestor)
            ancestor = ancestor[ancestor]

    def _depth(self, k: int) -> int:
        d, b = 0, self.body_parent[k]
        while b > 0:
            d, b = d + 1, self.body_parent[b - 1]
        return d

    def path(self, body: int) -> list[int]:
        """Actuated joints from the root down to ``body`` (its own joint last)."""
        out = []
        while body > 0:
            out.append(body - 1)
            body = int(self.body_parent[body - 1])
        return out[::-1]

    def fk(self, q: np.ndarray) -> np.ndarray:
        """Body transforms ``(n + 1, 4, 4)`` in the root frame."""
        c, s = np.cos(q), np.sin(q)
        r = (c[:, None, None] * self._eye3 + (1.0 - c)[:, None, None] * self._aa
             + s[:, None, None] * self._k)
        t = np.empty((self.n + 2, 4, 4))  # bodies, then the world (identity) for pointer doubling
        t[0] = t[-1] = np.eye(4)
        t[1:-1] = self.origins
        if self._any_prismatic:
            p = self.prismatic
            r[p] = np.eye(3)
            t[1:-1][p, :3, 3] += np.einsum("kij,kj->ki", self.origins[p, :3, :3], self.axes[p]) * q[p, None]
        t[1:-1, :3, :3] = self.origins[:, :3, :3] @ r
        # Each body's transform relative to an ancestor twice as far up every round.
        for ancestors in self._doubling:
            t = t[ancestors] @ t
        return t[:-1]

    def link_frames(self, q: np.ndarray) -> dict[str, np.ndarray]:
        t = self.fk(q)
        return {link: t[b] @ self.link_T[link] for link, b in self.link_body.items()}


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.cross`` over the last axis of broadcast arrays, without its axis bookkeeping."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def _side(name: str) -> str | None:
    low = name.lower()
    tokens = set(low.replace("-", "_").replace(".", "_").split("_"))
    if "left" in low or "l" in tokens:
        return "left"
    if "right" in low or "r" in tokens:
        return "right"
    return None


def load_map(path: str | Path) -> dict[str, str]:
    """A body map YAML: ``left_knee: JOINT`` ... (keys :data:`MAP_KEYS`); one-line errors."""
    from ruamel.yaml import YAML, YAMLError

    path = Path(path)
    try:
        data = YAML(typ="safe").load(files.read_bytes(path, "body map").decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise MotionStyleError(f"{path}: cannot read the body map ({exc})") from None
    except YAMLError as exc:
        raise MotionStyleError(f"{path}: not valid YAML ({' '.join(str(exc).split())})") from None
    except RecursionError:
        raise MotionStyleError(f"{path}: not a body map (YAML nested too deeply)") from None
    except ValueError as exc:  # an int of over 4300 digits
        raise MotionStyleError(f"{path}: not a body map ({' '.join(str(exc).split())})") from None
    if not isinstance(data, dict) or not all(isinstance(v, str) for v in data.values()):
        raise MotionStyleError(f"{path}: a body map is a mapping of {', '.join(MAP_KEYS)} to names")
    unknown = set(data) - set(MAP_KEYS)
    if unknown:
        raise MotionStyleError(f"{path}: unknown keys {sorted(map(str, unknown))}; allowed: "
                               f"{', '.join(MAP_KEYS)}")
    return dict(data)


class RobotTarget:
    """Canonical-skeleton motion on a humanoid robot described by a URDF.

    ``RobotTarget(urdf)`` with ``urdf`` a path (or a :class:`RobotModel`); ``body_map``: a YAML
    path or dict naming the anchors (see the module docstring) where names do not say them.
    ``step(rotations, root, t)`` maps one frame (streaming, stateful: warm start, velocity limits);
    ``reset()`` starts a new stream; :attr:`base_pose` is the last frame's base; ``map_motion``
    maps a whole clip through ``step``.
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
        self.kin = _Kinematics(urdf)
        self.weights = weights or Weights()
        self.solver = solver
        self.ankle_height = float(ankle_height)  # the human's planted ankles, core frame (m)
        self.iterations = iterations
        self.names: list[str] = list(self.kin.names)
        self.lower, self.upper, self.velocity = self.kin.lower, self.kin.upper, self.kin.velocity
        self._neutral = np.clip(np.zeros(self.kin.n), self.lower, self.upper)
        self._eye3 = np.eye(3)
        self._build(dict(body_map or {}))
        self._human_setup()
        self.reset()

    # ------------------------------------------------------------------ the body map
    def _build(self, overrides: dict[str, str]) -> None:
        kin, src = self.kin, self.model.source
        t0 = kin.fk(np.zeros(kin.n))
        o0 = t0[1:, :3, 3]
        w0 = np.einsum("kij,kj->ki", t0[1:, :3, :3], kin.axes)
        names = kin.names
        points: list[tuple[int, np.ndarray]] = []  # (body, point in the body frame)

        def attach(body: int, world: np.ndarray) -> int:
            t = t0[body]
            points.append((body, t[:3, :3].T @ (world - t[:3, 3])))
            return len(points) - 1

        def centre(group: list[int]) -> np.ndarray:
            """The point nearest all the group's axis lines (nearest the first origin if parallel)."""
            a = 1e-3 * np.eye(3)
            b = 1e-3 * o0[group[0]]
            for k in group:
                proj = np.eye(3) - np.outer(w0[k], w0[k])
                a, b = a + proj, b + proj @ o0[k]
            return np.linalg.solve(a, b)

        def side_of(k: int) -> str | None:
            return _side(names[k]) or ("left" if o0[k, 1] > 0.01 else "right" if o0[k, 1] < -0.01 else None)

        def anchor(role: str, side: str) -> int:
            key = f"{side}_{role}"
            if key in overrides:
                if overrides[key] not in names:
                    raise MotionStyleError(f"{src}: the body map's {key} {overrides[key]!r} is no "
                                           f"actuated joint of the robot")
                return names.index(overrides[key])
            found = [k for k in range(kin.n) if role in names[k].lower() and side_of(k) == side]
            if not found:
                raise MotionStyleError(
                    f"{src}: no {side} {role} joint (an actuated joint named like '*{side}*{role}*'); "
                    f"is it a humanoid? Name it in a body map ({key}: JOINT_NAME)")
            return min(found, key=lambda k: len(kin.path(k + 1)))

        def subtree(k: int) -> list[int]:
            return [b for b in range(1, kin.n + 1) if k in kin.path(b)]

        def links_of(bodies: list[int]) -> list[str]:
            return [link for link, b in kin.link_body.items() if b in bodies]

        def world_of(link: str, local: np.ndarray) -> np.ndarray:
            t = t0[kin.link_body[link]] @ kin.link_T[link]
            return t[:3, :3] @ local + t[:3, 3]

        knee = {s: anchor("knee", s) for s in ("left", "right")}
        elbow = {s: anchor("elbow", s) for s in ("left", "right")}
        seg_names, seg_a, seg_b, seg_w, human = [], [], [], [], []
        w = self.weights
        feet = {}
        leg_lengths = []

        def segment(name, a, b, weight, h):
            seg_names.append(name)
            seg_a.append(a)
            seg_b.append(b)
            seg_w.append(weight)
            human.append(h)

        hip_pts, shoulder_pts = {}, {}
        for s, other in (("left", "right"), ("right", "left")):
            tag = s[0].upper()
            kp = kin.path(knee[s] + 1)
            shared = set(kin.path(knee[other] + 1))
            hips = [k for k in kp[:-1] if k not in shared]
            if not hips:
                raise MotionStyleError(f"{src}: no hip joints above the {s} knee {names[knee[s]]!r}")
            below = subtree(knee[s])
            foot_key = f"{s}_foot"
            if foot_key in overrides:
                if overrides[foot_key] not in kin.link_body:
                    raise MotionStyleError(f"{src}: the body map's {foot_key} {overrides[foot_key]!r} "
                                           f"is no link of the robot")
                foot = kin.link_body[overrides[foot_key]]
            else:
                foot = min(below, key=lambda b: (round(t0[b][2, 3], 3), -len(kin.path(b))))
            ankles = [k for k in kin.path(foot) if k not in kp and "toe" not in names[k].lower()]
            hip_c, knee_c = centre(hips), o0[knee[s]]
            contacts = [world_of(link, p) for link in links_of([foot]) if link in self.model.shapes
                        for p in self.model.shapes[link]]
            if contacts:
                contacts = np.array(contacts)
                contacts = contacts[contacts[:, 2] < contacts[:, 2].min() + 0.005]
            else:  # no primitive shapes: the foot body's origin stands in for its sole
                contacts = t0[foot][None, :3, 3]
            sole = contacts.mean(axis=0)
            ankle_c = centre(ankles) if ankles else sole
            hip_pts[s] = attach(int(kin.body_parent[hips[0]]), hip_c)
            knee_p = attach(int(kin.body_parent[knee[s]]), knee_c)
            ankle_p = attach(int(kin.body_parent[ankles[0]]) if ankles else foot, ankle_c)
            leg_lengths.append(np.linalg.norm(knee_c - hip_c) + np.linalg.norm(ankle_c - knee_c))
            segment(f"thigh_{tag}", hip_pts[s], knee_p, w.limb, (f"UpperLeg_{tag}", f"LowerLeg_{tag}"))
            segment(f"shin_{tag}", knee_p, ankle_p, w.limb, (f"LowerLeg_{tag}", f"Foot_{tag}"))
            rf = t0[foot][:3, :3]
            feet[s] = dict(body=foot, sole=attach(foot, sole),
                           contacts=[attach(foot, c) for c in contacts],
                           x=rf.T @ np.array([1.0, 0, 0]), z=rf.T @ np.array([0, 0, 1.0]),
                           joints=ankles, hips=hips, knee=knee[s])

            ep = kin.path(elbow[s] + 1)
            shared = set(kin.path(elbow[other] + 1))
            shoulders = [k for k in ep[:-1] if k not in shared]
            if not shoulders:
                raise MotionStyleError(f"{src}: no shoulder joints above the {s} elbow {names[elbow[s]]!r}")
            self._torso_joints = [k for k in ep[:-1] if k in shared]
            sh_c, el_c = centre(shoulders), o0[elbow[s]]
            shoulder_pts[s] = attach(int(kin.body_parent[shoulders[0]]), sh_c)
            elbow_p = attach(int(kin.body_parent[elbow[s]]), el_c)
            below = subtree(elbow[s])
            hand = max(below, key=lambda b: (len(kin.path(b)), np.linalg.norm(t0[b][:3, 3] - el_c)))
            wrists = [k for k in kin.path(hand) if k not in ep]

            def farthest(bodies, start):
                cands = [(link, np.zeros(3)) for link in links_of(bodies)]
                cands += [(link, self.model.coms[link]) for link in links_of(bodies) if link in self.model.coms]
                link, local = max(cands, key=lambda c: np.linalg.norm(world_of(*c) - start))
                return kin.link_body[link], world_of(link, local)

            segment(f"upper_arm_{tag}", shoulder_pts[s], elbow_p, w.limb,
                    (f"UpperArm_{tag}", f"LowerArm_{tag}"))
            if wrists:
                wr_c = centre(wrists)
                wrist_p = attach(int(kin.body_parent[wrists[0]]), wr_c)
                segment(f"forearm_{tag}", elbow_p, wrist_p, w.limb, (f"LowerArm_{tag}", f"Hand_{tag}"))
                hb, end = farthest([hand], wr_c)
                if np.linalg.norm(end - wr_c) > 0.02:
                    segment(f"hand_{tag}", wrist_p, attach(hb, end), w.hand, (f"Hand_{tag}", None))
            else:
                hb, end = farthest(below, el_c)
                segment(f"forearm_{tag}", elbow_p, attach(hb, end), w.limb, (f"LowerArm_{tag}", f"Hand_{tag}"))

        torso = self._torso_joints
        base_c = centre(torso) if torso else np.zeros(3)
        base_p = attach(int(kin.body_parent[torso[0]]) if torso else 0, base_c)
        n_pts = len(points)
        # Segment vectors as rows of S @ P; the torso ends midway between the shoulders.
        mid = np.zeros(n_pts)
        mid[[shoulder_pts["left"], shoulder_pts["right"]]] = 0.5
        rows = []
        for a, b in zip(seg_a, seg_b):
            r = np.zeros(n_pts)
            r[b] += 1.0
            r[a] -= 1.0
            rows.append(r)
        base_row = mid.copy()
        base_row[base_p] -= 1.0
        line = np.zeros(n_pts)
        line[shoulder_pts["left"]], line[shoulder_pts["right"]] = 1.0, -1.0
        rows = [base_row, line] + rows
        seg_names = ["torso", "shoulders"] + seg_names
        seg_w = [w.torso, w.shoulders] + seg_w
        human = [("Hips", "shoulders"), ("UpperArm_R", "UpperArm_L")] + human
        self._S = np.array(rows)
        self.segments = seg_names
        self._seg_w = np.array(seg_w)
        self._human_segments = human
        self._pt_body = np.array([b for b, _ in points])
        self._pt_local = np.array([p for _, p in points])
        self._pt_anc = kin.anc[self._pt_body]
        self._feet = [feet["left"], feet["right"]]
        self._foot_bodies = np.array([f["body"] for f in self._feet])
        self._foot_axes = np.array([[f["x"], f["z"]] for f in self._feet])  # (2, 2, 3)
        self._contacts = [np.array(f["contacts"]) for f in self._feet]
        self._height_pts = np.concatenate([[f["sole"]] + list(f["contacts"]) for f in self._feet])
        self._height_counts = np.array([1 + len(f["contacts"]) for f in self._feet])
        self._height_is_sole = np.concatenate([[True] + [False] * len(f["contacts"]) for f in self._feet])
        self.leg_length = float(np.mean(leg_lengths))
        lowest = min(float(t0[self._pt_body[c]][2, 3] + (t0[self._pt_body[c]][:3, :3] @ self._pt_local[c])[2])
                     for f in self._contacts for c in f)
        self.standing_height = -lowest  # root height above the soles at the zero pose
        self.body_map = {
            "knee": {s: names[knee[s]] for s in knee}, "elbow": {s: names[elbow[s]] for s in elbow},
            "hip": {s: [names[k] for k in feet[s]["hips"]] for s in feet},
            "ankle": {s: [names[k] for k in feet[s]["joints"]] for s in feet},
            "foot": {s: [link for link, b in kin.link_body.items() if b == feet[s]["body"]][0] for s in feet},
            "torso": [names[k] for k in torso], "segments": list(self.segments),
        }

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
        ends = []
        for a, b in self._human_segments:
            ra = [idx("UpperArm_L"), idx("UpperArm_R")] if a == "shoulders" else [idx(a)]
            rb = ([idx("UpperArm_L"), idx("UpperArm_R")] if b == "shoulders" else [] if b is None
                  else [idx(b)])
            ends.append((ra, rb))
        n = len(ends)
        self._hA = np.zeros((n, sk.n_joints))
        self._hB = np.zeros((n, sk.n_joints))
        self._hand_rows = []
        for i, (ra, rb) in enumerate(ends):
            self._hA[i, ra] = 1.0 / len(ra)
            if rb:
                self._hB[i, rb] = 1.0 / len(rb)
            else:
                self._hand_rows.append((i, 0 if ra[0] == self._hands[0] else 1))

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
        rotations = np.asarray(rotations, dtype=np.float64)
        root = np.asarray(root, dtype=np.float64)
        if rotations.shape != (self._sk.n_joints, 4) or root.shape != (3,):
            raise MotionStyleError(f"a frame is (22, 4) rotations and a (3,) root, got {rotations.shape} "
                                   f"and {root.shape}")
        if not (np.isfinite(rotations).all() and np.isfinite(root).all()):
            raise MotionStyleError("non-finite values in the frame")
        g_rot, g_pos = self._human(rotations, root)
        dt = None if self._t is None else float(t) - self._t
        fresh = dt is None or dt > GAP_SECONDS
        # Base orientation: the human pelvis's turn from its T-pose, in REP-103 axes.
        r_base = _C @ (g_rot[0] @ self._rest_hips.T) @ _C.T
        p_ros = g_pos @ _C.T
        up = r_base[2]  # world Z in the base frame
        # Human bone directions, in the base frame.
        v = self._hB @ p_ros - self._hA @ p_ros
        for i, side in self._hand_rows:
            v[i] = _C @ (g_rot[1 + side][:, 0] * self._hand_sign[side])
        d_h = v / np.linalg.norm(v, axis=1, keepdims=True)
        d_h = d_h @ r_base  # R^T d for each row
        # Feet: planted, and heading.
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
        contact = self._contact
        # Foot frame targets: the human foot's heading, and its pitch relative to its planted pitch
        # (flat on the floor when planted, toes down at push-off).
        f = p_ros[self._toes] - ankles
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
        q_ik, z = x[:-1], float(x[-1])
        # Limits: count before clamping, then clamp velocity and position.
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
        q = safe
        # Planted feet back on the floor after the clamp: their lowest sole points on it (on
        # average), and then no sole point of either foot under it, as a real floor holds a robot.
        pts, frames = self._points(q)
        foot_h = np.array([float((pts[c] @ up).min()) + z for c in self._contacts])
        weight = min(float(contact.sum()), 1.0)
        shift = float((contact * foot_h).sum() / max(contact.sum(), 1e-9)) if weight else 0.0
        shift = min(shift, float(foot_h.min()))
        z -= weight * shift
        foot_h -= weight * shift
        seg = self._S @ pts
        d_r = seg / np.linalg.norm(seg, axis=1, keepdims=True)
        self.last = {"angles": np.degrees(np.arccos(np.clip((d_r * d_h).sum(axis=1), -1.0, 1.0))),
                     "foot_heights": foot_h, "planted": planted,
                     "contact": contact.copy()}
        base_xy = self.scale * p_ros[self._hips, :2]
        self.base_pose = (np.array([base_xy[0], base_xy[1], z]), rot.from_matrix(r_base))
        self._q, self._z, self._t, self._h_prev = q, z, float(t), h
        return q.copy()

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
        lever = _cross(axes_w[None, :, :], pts[:, None, :] - orig[None, :, :])
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
        de = _cross(axes_w[None, None, :, :], e[:, :, None, :]) * fa[:, None, :, None]  # (2,2,J,3)
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
        x = np.clip(x0, lo, hi)
        if self.solver == "scipy":
            from scipy.optimize import least_squares

            cache = {}

            def both(v):
                key = v.tobytes()
                if key not in cache:
                    cache.clear()
                    cache[key] = self._residuals(v, ctx)
                return cache[key]

            inside = np.clip(x, np.nextafter(lo, hi), np.nextafter(hi, lo))
            res = least_squares(lambda v: both(v)[0], inside, jac=lambda v: both(v)[1],
                                bounds=(lo, hi), method="trf", max_nfev=iters * 4,
                                xtol=1e-6, ftol=1e-6)
            return np.clip(res.x, lo, hi)
        r, jac = self._residuals(x, ctx)
        cost = r @ r
        lam = 1e-3
        for _ in range(iters):
            g = jac.T @ r
            hess = jac.T @ jac
            free = ~(((x <= lo) & (g > 0)) | ((x >= hi) & (g < 0)))
            hf = hess[np.ix_(free, free)]
            hf[np.diag_indices_from(hf)] += lam * (1.0 + np.diag(hf))
            step = np.zeros_like(x)
            step[free] = -np.linalg.solve(hf, g[free])
            xn = np.clip(x + step, lo, hi)
            rn, jn = self._residuals(xn, ctx)
            cn = rn @ rn
            if cn < cost:
                done = np.abs(xn - x).max() < 1e-3 or (lam < 1e-2 and cost - cn < 1e-6 * (1.0 + cost))
                x, r, jac, cost = xn, rn, jn, cn
                lam = max(lam * 0.3, 1e-7)
                if done:
                    break
            else:
                lam *= 10.0
                if lam > 1e4:
                    break
        return x

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


def planted_feet(motion: Motion) -> np.ndarray:
    """``(T, 2)`` left/right: the human's ankle (``Foot_L``/``Foot_R``) within
    :data:`EVAL_CONTACT_HEIGHT` of its clip's low-percentile height and slower than
    :data:`EVAL_SPEED` horizontally (how the package judges contact, :func:`metrics.foot_skating`)."""
    sk = motion.skeleton
    ankles = [sk.index("Foot_L"), sk.index("Foot_R")]
    p = motion.global_positions()[:, ankles]
    h = p[..., 1]
    low = h <= np.percentile(h, EVAL_FLOOR_PERCENTILE, axis=0) + EVAL_CONTACT_HEIGHT
    v = np.zeros_like(h)
    v[1:] = np.linalg.norm(np.diff(p[..., [0, 2]], axis=0), axis=-1) * motion.fps
    v[0] = v[1] if len(v) > 1 else 0.0
    return low & (v < EVAL_SPEED)


def evaluate(mapping: Mapping, motion: Motion, target: RobotTarget) -> dict:
    """The figures of one mapped clip: limit counts, link-vs-bone angles, planted-sole heights and
    time per frame; after-clamp limit violations recounted from the output."""
    q = mapping.positions
    dt = 1.0 / motion.fps
    pos_after = int(((q < target.lower - 1e-9) | (q > target.upper + 1e-9)).sum())
    vel_after = int((np.abs(np.diff(q, axis=0)) > target.velocity * dt + 1e-9).sum())
    planted = planted_feet(motion)
    err = np.abs(mapping.foot_heights[planted])
    return {
        "frames": int(motion.n_frames),
        **{k: int(v) for k, v in mapping.stats.items() if k != "frames"},
        "position_violations_after": pos_after,
        "velocity_violations_after": vel_after,
        "finite": bool(np.isfinite(q).all()),
        "angles": mapping.angles,
        "planted_errors": err,
        "ms_per_frame": 1000.0 * mapping.seconds / max(motion.n_frames, 1),
    }
