"""A procedural neutral walk, run and wave on the canonical skeleton, for the built-in demo.

No recorded motion can ship with the package, so the demo performer is made of sinusoids and
splines. Each joint gets a rotation in world-aligned axes applied on top of the canonical T-pose (see
:func:`_pose_on_tpose`), so "hip flexion" is simply a rotation of the thigh about the body's lateral
axis. The pelvis height keeps the lower foot on the floor; in stance a thigh turns back at a constant
rate and the pelvis moves at the matching constant speed, so the supporting foot stays nearly planted.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from motion_style_ros.core import rotations as rot
from motion_style_ros.core.motion import Motion, forward_kinematics
from motion_style_ros.core.retarget import tpose
from motion_style_ros.core.skeleton import canonical
from motion_style_ros.errors import MotionStyleError

KINDS = ("walk", "run", "wave")
_X, _Y, _Z = np.eye(3)


@dataclass(frozen=True)
class _Gait:
    period: float  # seconds per cycle (two steps)
    stance: float  # fraction of the cycle a foot is on the floor
    hip: float  # thigh swing amplitude, degrees
    hip_bias: float  # thighs swing more to the front than to the back
    knee: float  # extra knee flexion at mid-swing
    knee_stance: float  # knee flexion on the supporting leg
    arm: float  # upper-arm swing amplitude
    elbow: float  # elbow flexion
    lean: float  # trunk forward lean
    yaw: float  # pelvis yaw amplitude (the chest counter-rotates)


_GAITS = {
    "walk": _Gait(period=1.1, stance=0.6, hip=24.0, hip_bias=5.0, knee=55.0, knee_stance=8.0,
                  arm=16.0, elbow=18.0, lean=3.0, yaw=5.0),
    "run": _Gait(period=0.72, stance=0.5, hip=32.0, hip_bias=12.0, knee=85.0, knee_stance=22.0,
                 arm=30.0, elbow=80.0, lean=9.0, yaw=8.0),
}


def _about(axis: np.ndarray, degrees: np.ndarray) -> np.ndarray:
    degrees = np.asarray(degrees, dtype=np.float64)
    return rot.from_axis_angle(np.broadcast_to(axis, degrees.shape + (3,)), np.deg2rad(degrees))


def _pose_on_tpose(world: dict[str, np.ndarray], frames: int) -> np.ndarray:
    """Local rotations ``(T, 22, 4)`` that apply ``world[bone]`` (``(T, 4)``) to each bone as a rotation
    in the parent's T-pose-aligned axes: with ``L = L_T G_T^-1 A G_T`` a bone's global rotation is
    ``A_root ... A_parent A G_T``."""
    skel = canonical()
    t = tpose(skel)
    a = rot.identity((frames, skel.n_joints))
    for name, q in world.items():
        a[:, skel.index(name)] = q
    g_t = t.rotations
    return rot.multiply(t.local_rotations, rot.multiply(rot.conjugate(g_t), rot.multiply(a, g_t)))


def _leg_cycle(u: np.ndarray, stance: float) -> tuple[np.ndarray, np.ndarray]:
    """Thigh swing in [-1, 1] (+1 forward) and the swing-phase fraction (0 in stance) at cycle
    fraction ``u``: during stance the thigh turns back at a constant rate (so a constant pelvis
    speed keeps the foot planted), then a cubic Hermite brings it forward with matching slopes."""
    tau = np.clip((u - stance) / (1.0 - stance), 0.0, 1.0)
    slope = -2.0 / stance * (1.0 - stance)  # d(thigh)/d(tau) at both ends of the swing
    hermite = (-(2 * tau**3 - 3 * tau**2 + 1) + (-2 * tau**3 + 3 * tau**2)
               + slope * (tau**3 - 2 * tau**2 + tau) + slope * (tau**3 - tau**2))
    return np.where(u < stance, 1.0 - 2.0 * u / stance, hermite), np.where(u < stance, 0.0, tau)


def _locomotion(gait: _Gait, times: np.ndarray) -> dict[str, np.ndarray]:
    cycle = times / gait.period
    world = {}
    thighs = {}
    for side, shift in (("L", 0.0), ("R", 0.5)):
        u = np.mod(cycle + shift, 1.0)  # 0: this foot strikes the floor
        thigh, tau = _leg_cycle(u, gait.stance)
        thighs[side] = thigh
        hip = gait.hip_bias + gait.hip * thigh
        knee = (gait.knee_stance * np.sin(np.pi * np.minimum(u / gait.stance, 1.0)) ** 2
                + gait.knee * np.sin(np.pi * tau**0.7) ** 2)  # early peak: the toes clear the floor
        world[f"UpperLeg_{side}"] = _about(_X, -hip)
        world[f"LowerLeg_{side}"] = _about(_X, knee)
        # Flat on the floor in stance, toes up in swing.
        world[f"Foot_{side}"] = _about(_X, hip - knee - 8.0 * np.sin(np.pi * tau))
    for side, other, sign in (("L", "R", 1.0), ("R", "L", -1.0)):
        arm = gait.arm * thighs[other]  # forward with the opposite leg
        world[f"UpperArm_{side}"] = rot.multiply(_about(_X, -arm), _about(_Z, -sign * 78.0))
        world[f"LowerArm_{side}"] = _about(_Y, -sign * gait.elbow * (1.0 + 0.3 * thighs[other]))
    mid_stance_l = np.cos(2 * np.pi * (cycle - 0.5 * gait.stance))  # +1 when the left foot carries
    yaw = -gait.yaw * thighs["L"]  # the forward leg's hip leads
    sway = 2.0 * mid_stance_l
    world["Hips"] = rot.multiply(_about(_Y, yaw), _about(_Z, sway))
    world["Spine"] = _about(_X, gait.lean + 1.5 * mid_stance_l**2)
    world["Chest"] = rot.multiply(_about(_Y, -1.6 * yaw), _about(_Z, -sway))
    world["Head"] = _about(_X, -gait.lean)
    return world


def _wave(times: np.ndarray) -> dict[str, np.ndarray]:
    beat = np.sin(2 * np.pi * 1.6 * times)
    breath = np.sin(2 * np.pi * 0.25 * times)
    return {
        "Hips": _about(_Z, 1.5 * breath),
        "Spine": _about(_Z, -1.0 * breath),
        "Head": _about(_Z, 4.0 * beat),
        "UpperArm_L": _about(_Z, -80.0),
        "LowerArm_L": _about(_Y, -10.0),
        "UpperArm_R": rot.multiply(_about(_X, 15.0), _about(_Z, -25.0 + 3.0 * beat)),
        "LowerArm_R": _about(_Z, -65.0 + 28.0 * beat),
        "Hand_R": _about(_Z, 10.0 * beat),
        "UpperLeg_L": _about(_Z, 3.0),
        "UpperLeg_R": _about(_Z, -3.0),
    }


def _positions(rotations: np.ndarray) -> np.ndarray:
    """Global joint positions with the pelvis at its rest offset."""
    skel = canonical()
    offsets = np.broadcast_to(skel.offsets, rotations.shape[:-1] + (3,))
    return forward_kinematics(skel, rotations, offsets)[1]


def _grounded(rotations: np.ndarray) -> np.ndarray:
    """Pelvis positions ``(T, 3)`` in place (x = z = 0) with the lowest foot joint on the floor."""
    skel = canonical()
    rest = skel.offsets[skel.pelvis]
    g_pos = _positions(rotations)
    feet = list(skel.feet)
    rest_floor = tpose(skel).positions[feet, 1].min()
    root = np.zeros(rotations.shape[:1] + (3,))
    root[:, 1] = rest[1] - (g_pos[:, feet, 1].min(axis=1) - rest_floor)
    return root


@functools.cache
def _speed(kind: str) -> float:
    """Forward speed (m/s) that keeps the supporting foot still: how far the left ankle travels back
    under the pelvis from heel strike to toe-off, over the stance time."""
    gait = _GAITS[kind]
    skel = canonical()
    times = np.array([0.0, gait.stance]) * gait.period
    rotations = _pose_on_tpose(_locomotion(gait, times), len(times))
    z = _positions(rotations)[:, skel.index("Foot_L"), 2]
    return float((z[0] - z[1]) / times[1])


def synthetic_motion(kind: str, fps: float = 60.0, duration: float = 4.0,
                     start: float = 0.0) -> Motion:
    """``kind`` (walk, run or wave) on the canonical skeleton, frames at ``start + k / fps``.

    The pose is periodic and the walk/run travel along +Z at a constant speed, so consecutive chunks
    (``start`` advancing by their duration) join seamlessly into an endless stream.
    """
    if kind not in KINDS:
        raise MotionStyleError(f"unknown synthetic motion {kind!r}; choose one of {', '.join(KINDS)}")
    if not (np.isfinite(fps) and fps > 0 and np.isfinite(duration) and duration > 0):
        raise MotionStyleError(f"synthetic motion needs fps > 0 and duration > 0, got {fps}, {duration}")
    times = start + np.arange(max(round(duration * fps), 1)) / fps
    world = _wave(times) if kind == "wave" else _locomotion(_GAITS[kind], times)
    rotations = _pose_on_tpose(world, len(times))
    root = _grounded(rotations)
    if kind != "wave":
        gait = _GAITS[kind]
        # The pelvis sways over the supporting foot.
        root[:, 0] = 0.02 * np.cos(2 * np.pi * (times / gait.period - 0.5 * gait.stance))
        root[:, 2] = _speed(kind) * times
    return Motion.from_rotations(canonical(), rotations, root, fps)
