"""Canonical-skeleton clips from BVH files: recognising a file already on the canonical (Bandai
Namco) skeleton, reading its arrays, and :func:`canonical_clip`, the loader every user-facing path
(the live node's reference clips, ``stylize``, ``style``, ``robot``, ``bench``) reads clips with.
Apart from the dataset indexer, so that the runtime and the nodes need no dataset code."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from motion_style_ros.core import rotations as rot
from motion_style_ros.core.conform import ground
from motion_style_ros.core.motion import Motion
from motion_style_ros.core.retarget import retarget
from motion_style_ros.core.skeleton import canonical
from motion_style_ros.errors import MotionStyleError
from motion_style_ros.io import bvh
from motion_style_ros.io.resources import rotation_stats

# Largest distance (m) of a bone's per-frame translation from the canonical rest offset; the
# recordings deviate by at most 0.4 mm, another skeleton by centimetres.
BONE_TOLERANCE = 2e-3


def is_canonical(clip: bvh.BvhClip) -> bool:
    """A BVH on the canonical skeleton (a Bandai Namco file, or this package's output)."""
    sk = canonical()
    return clip.skeleton.names == sk.names and clip.skeleton.parents == sk.parents


def canonical_arrays(clip: bvh.BvhClip, path: Path | str) -> tuple[np.ndarray, np.ndarray]:
    """Local rotations ``(T, 22, 4)`` and the Hips translation ``(T, 3)`` (m) of a canonical-skeleton
    BVH in centimetres, at any rate.

    ``joint_Root`` is static in almost every Bandai file, but four dataset-1 clips (short in-place
    cycles) carry their trajectory on it; it is folded into Hips so that the canonical skeleton's
    static root loses nothing.
    """
    sk = canonical()
    if not is_canonical(clip):
        raise MotionStyleError(f"{path}: not the 22-joint Bandai Namco skeleton")
    m = clip.to_motion(scale=0.01)
    error = np.abs(m.positions[:, 2:] - sk.offsets[2:]).max(axis=(0, 2))
    j = int(np.argmax(error))
    if error[j] > BONE_TOLERANCE:
        raise MotionStyleError(
            f"{path}: joint {sk.names[j + 2]} is {100 * error[j]:.1f} cm from the canonical "
            "skeleton's rest offset; the clip does not fit the canonical skeleton"
        )
    root_q = m.rotations[:, 0]
    rotations = m.rotations.copy()
    rotations[:, 0] = rot.identity()
    rotations[:, 1] = rot.multiply(root_q, m.rotations[:, 1])
    hips = m.positions[:, 0] + rot.rotate(root_q, m.positions[:, 1])
    return rotations, hips


def canonical_clip(path: str) -> Motion:
    """A humanoid BVH clip as the stylizers take it: on the canonical skeleton (retargeted when it
    is another rig's, its planted ankles at the training data's height; the sessions conform its
    arm rolls); a missing or bad file is a one-line :class:`MotionStyleError`."""
    clip = bvh.read(path)
    if is_canonical(clip):  # Bandai Namco files and this package's own output, in centimetres
        return Motion.from_rotations(canonical(), *canonical_arrays(clip, path), clip.fps).check_finite(path)
    return ground(retarget(clip.to_motion().check_finite(path), canonical()), rotation_stats())
