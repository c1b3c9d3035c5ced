"""How well a clip mapped onto a robot keeps the motion (``motion-style robot check``): limit counts
before and after clamping, link-vs-bone angles, the planted soles' heights above the floor and the
time per frame of a :class:`~motion_style_ros.runtime.robot_target.RobotTarget` mapping."""

from __future__ import annotations

import numpy as np

from motion_style_ros.core.motion import Motion
from motion_style_ros.runtime.robot_target import Mapping, RobotTarget

# Evaluation (offline, whole clips) judges a human foot planted as metrics.foot_skating does:
# ankle within EVAL_CONTACT_HEIGHT of its clip's EVAL_FLOOR_PERCENTILE-th height percentile, and slow.
EVAL_CONTACT_HEIGHT = 0.01
EVAL_FLOOR_PERCENTILE = 5.0
EVAL_SPEED = 0.25


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
