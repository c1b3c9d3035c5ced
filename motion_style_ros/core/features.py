"""Per-frame model features of a canonical-skeleton motion, computed causally, and their inverse.

Frame ``t`` uses frames ``<= t`` only (backward differences, no smoothing over the clip), so the
same function serves offline training and live streams. Everything is expressed in the
character's *facing frame*: the yaw of the body about +Y, from the left-right axis of hips and
shoulders. That makes features independent of where the performer stands and which way they face.

Layout (``feature_layout``), per frame:

- ``root`` (4): forward-plane velocity ``vx, vz`` (m/s, facing frame of frame t), pelvis height
  (m), yaw rate (rad/s);
- ``rot6d`` (6 per joint): local rotations in 6D; the pelvis's is relative to the facing frame;
- ``pos`` (3 per joint): joint positions relative to the pelvis's ground point, facing frame (m);
- ``vel`` (3 per joint): joint velocities, facing frame (m/s);
- ``contact`` (1 per foot joint): 1 where the foot joint is low and still.

Joints are the pelvis and its descendants (the canonical skeleton's static ``joint_Root`` is left
out). :func:`decode` rebuilds a motion from ``root`` and ``rot6d``; ``pos``, ``vel`` and
``contact`` are redundant views for models and losses.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from motion_style_ros.core import rotations as rot
from motion_style_ros.core.motion import Motion
from motion_style_ros.core.skeleton import Skeleton, canonical
from motion_style_ros.errors import MotionStyleError

FEATURE_VERSION = 1
UP = np.array([0.0, 1.0, 0.0])

# Contact: foot joint within this height of the floor (m) and slower than CONTACT_SPEED (m/s).
CONTACT_HEIGHT = {"Foot_L": 0.16, "Foot_R": 0.16, "Toes_L": 0.08, "Toes_R": 0.08}
CONTACT_SPEED = 0.6

_ACROSS = ("UpperLeg_L", "UpperLeg_R", "UpperArm_L", "UpperArm_R")


@dataclass(frozen=True)
class FeatureLayout:
    joints: tuple[int, ...]  # skeleton joints described by the per-joint blocks
    slices: dict[str, slice]

    @property
    def size(self) -> int:
        return max(s.stop for s in self.slices.values())


def feature_layout(skeleton: Skeleton | None = None) -> FeatureLayout:
    sk = skeleton or canonical()
    joints = tuple(j for j in range(sk.pelvis, sk.n_joints) if _descends(sk, j, sk.pelvis))
    n = len(joints)
    sizes = {"root": 4, "rot6d": 6 * n, "pos": 3 * n, "vel": 3 * n, "contact": len(sk.feet)}
    slices, start = {}, 0
    for name, size in sizes.items():
        slices[name] = slice(start, start + size)
        start += size
    return FeatureLayout(joints, slices)


def _descends(sk: Skeleton, j: int, ancestor: int) -> bool:
    while j > ancestor:
        j = sk.parents[j]
    return j == ancestor


def _check_canonical(sk: Skeleton) -> None:
    missing = [n for n in _ACROSS + tuple(CONTACT_HEIGHT) if n not in sk.names]
    if missing:
        raise MotionStyleError(
            f"features need the canonical skeleton; missing joints {', '.join(missing)} "
            "(retarget the motion first)"
        )


def facing_yaw(global_positions: np.ndarray, skeleton: Skeleton) -> np.ndarray:
    """Heading of the body (radians about +Y, 0 = facing +Z) from hips and shoulders, per frame."""
    p = global_positions
    ul, ur, al, ar = (skeleton.index(n) for n in _ACROSS)
    across = (p[..., ul, :] - p[..., ur, :]) + (p[..., al, :] - p[..., ar, :])
    forward = np.cross(across, UP)
    return np.arctan2(forward[..., 0], forward[..., 2])


def foot_contacts(global_positions: np.ndarray, skeleton: Skeleton, fps: float) -> np.ndarray:
    """``(T, n_feet)`` 0/1 contacts: low and slow, speed by backward difference (causal)."""
    feet = list(skeleton.feet)
    p = global_positions[:, feet]
    speed = np.zeros(p.shape[:2])
    speed[1:] = np.linalg.norm(p[1:] - p[:-1], axis=-1) * fps
    heights = np.array([CONTACT_HEIGHT.get(skeleton.names[j], 0.1) for j in feet])
    return ((p[..., 1] < heights) & (speed < CONTACT_SPEED)).astype(np.float32)


def _backward_diff(x: np.ndarray, fps: float) -> np.ndarray:
    d = np.zeros_like(x)
    d[1:] = (x[1:] - x[:-1]) * fps
    return d


def _wrap(angle: np.ndarray) -> np.ndarray:
    return (angle + np.pi) % (2 * np.pi) - np.pi


def encode(motion: Motion) -> np.ndarray:
    """``(T, F)`` float32 features of a canonical-skeleton motion (see module docstring)."""
    sk = motion.skeleton
    _check_canonical(sk)
    lay = feature_layout(sk)
    joints = list(lay.joints)
    g_rot, g_pos = motion.global_transforms()
    t = motion.n_frames

    yaw = facing_yaw(g_pos, sk)
    inv_face = rot.conjugate(rot.from_yaw(yaw))[:, None]  # (T, 1, 4)
    pelvis = g_pos[:, sk.pelvis]
    ground = pelvis * np.array([1.0, 0.0, 1.0])

    out = np.empty((t, lay.size), dtype=np.float32)
    root_vel = rot.rotate(inv_face[:, 0], _backward_diff(ground, motion.fps))
    yaw_rate = np.zeros(t)
    yaw_rate[1:] = _wrap(yaw[1:] - yaw[:-1]) * motion.fps
    out[:, lay.slices["root"]] = np.stack(
        [root_vel[:, 0], root_vel[:, 2], pelvis[:, 1], yaw_rate], axis=-1
    )

    local = motion.rotations[:, joints].copy()
    local[:, 0] = rot.multiply(inv_face[:, 0], g_rot[:, sk.pelvis])  # pelvis relative to facing
    out[:, lay.slices["rot6d"]] = rot.to_6d(local).reshape(t, -1)

    rel = rot.rotate(inv_face, g_pos[:, joints] - ground[:, None])
    out[:, lay.slices["pos"]] = rel.reshape(t, -1)
    vel = rot.rotate(inv_face, _backward_diff(g_pos[:, joints], motion.fps))
    out[:, lay.slices["vel"]] = vel.reshape(t, -1)
    out[:, lay.slices["contact"]] = foot_contacts(g_pos, sk, motion.fps)
    return out


def decode(
    features: np.ndarray,
    fps: float,
    skeleton: Skeleton | None = None,
    start_ground: np.ndarray | None = None,
    start_yaw: float = 0.0,
) -> Motion:
    """Rebuild a motion from ``root`` and ``rot6d`` features by integrating the root velocities.

    Frame 0's facing frame is placed at ``start_ground`` (x, 0, z) with heading ``start_yaw``;
    later frames integrate yaw rate first, then velocity in the new facing frame, which inverts
    :func:`encode` exactly.
    """
    sk = skeleton or canonical()
    lay = feature_layout(sk)
    f = np.asarray(features, dtype=np.float64)
    if f.ndim != 2 or f.shape[1] != lay.size:
        raise MotionStyleError(f"features of shape {f.shape}; expected (T, {lay.size})")
    t = f.shape[0]
    root = f[:, lay.slices["root"]]
    yaw = start_yaw + np.concatenate([[0.0], np.cumsum(root[1:, 3]) / fps])
    face = rot.from_yaw(yaw)
    step = rot.rotate(face, np.stack([root[:, 0], np.zeros(t), root[:, 1]], axis=-1)) / fps
    step[0] = 0.0
    ground = np.cumsum(step, axis=0)
    if start_ground is not None:
        ground += np.asarray(start_ground, dtype=np.float64) * np.array([1.0, 0.0, 1.0])

    rotations = rot.identity((t, sk.n_joints))
    local = rot.from_6d(f[:, lay.slices["rot6d"]].reshape(t, len(lay.joints), 6))
    rotations[:, list(lay.joints)] = local
    # Joints above the pelvis (the canonical static root) stay identity at the origin.
    rotations[:, sk.pelvis] = rot.multiply(face, local[:, 0])
    root_pos = ground + root[:, 2:3] * UP
    return Motion.from_rotations(sk, rotations, root_pos, fps)
