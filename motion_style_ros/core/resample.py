"""Resampling clips between frame rates (30/60/120 Hz streams and datasets)."""

from __future__ import annotations

import numpy as np

from motion_style_ros.core import rotations as rot
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
