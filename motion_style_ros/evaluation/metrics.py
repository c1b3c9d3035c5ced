"""Motion quality metrics: pure functions on motions and embedding arrays (numpy + scipy).

Each one answers a question a stylizer's output can get wrong: does it look like the target
style (Frechet distance in a judge's embedding space), did it keep the content (content
consistency), do the feet slide, is it jittery (jerk), did it stretch the skeleton (bone lengths).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from motion_style_ros.core.features import feature_layout
from motion_style_ros.core.motion import Motion
from motion_style_ros.core.skeleton import Skeleton

# A foot joint is in contact while it is within CONTACT_HEIGHT (m) of its own floor height, the
# FLOOR_PERCENTILE-th percentile of its height over the clip (a low percentile, not the minimum,
# so that one glitched frame below the ground does not move the floor).
CONTACT_HEIGHT = 0.01
FLOOR_PERCENTILE = 5.0


def frechet_distance(a: np.ndarray, b: np.ndarray, eps: float = 1e-6) -> float:
    """Frechet distance between Gaussians fitted to two sets of row vectors ``(N, D)``, ``(M, D)``.

    ``eps`` times the identity is added to both covariances: with a few dozen samples in 64
    dimensions they are singular, and the matrix square root of their product would be unstable.
    """
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if a.ndim != 2 or b.ndim != 2 or a.shape[1] != b.shape[1] or min(len(a), len(b)) < 2:
        raise ValueError(f"need two sets of at least 2 row vectors of one size, got {a.shape} and {b.shape}")
    ridge = eps * np.eye(a.shape[1])
    cov_a, cov_b = np.cov(a, rowvar=False) + ridge, np.cov(b, rowvar=False) + ridge
    # The product of two PSD matrices has real non-negative eigenvalues; rounding can leave tiny
    # imaginary parts in its square root, which carry no information.
    cross = scipy.linalg.sqrtm(cov_a @ cov_b).real
    diff = a.mean(axis=0) - b.mean(axis=0)
    return float(max(diff @ diff + np.trace(cov_a + cov_b - 2.0 * cross), 0.0))


def foot_skating(motion: Motion, contact_height: float = CONTACT_HEIGHT) -> float:
    """Mean horizontal speed (m/s) of the foot joints between consecutive frames both in contact.

    Contact is by height alone (not speed, which would hide fast sliding). NaN when no foot
    joint is ever in contact for two consecutive frames.
    """
    feet = list(motion.skeleton.feet)
    p = motion.global_positions()[:, feet]
    height = p[..., 1]
    contact = height <= np.percentile(height, FLOOR_PERCENTILE, axis=0) + contact_height
    both = contact[1:] & contact[:-1]
    if not both.any():
        return float("nan")
    speed = np.linalg.norm(np.diff(p[..., [0, 2]], axis=0), axis=-1) * motion.fps
    return float(speed[both].mean())


def jerk(motion: Motion) -> float:
    """Mean norm of the third derivative of joint positions (m/s^3), by third finite differences.

    Joints above the pelvis (the canonical skeleton's static root) are left out.
    """
    if motion.n_frames < 4:
        raise ValueError(f"jerk needs at least 4 frames, got {motion.n_frames}")
    joints = list(feature_layout(motion.skeleton).joints)
    p = motion.global_positions()[:, joints]
    return float(np.linalg.norm(np.diff(p, n=3, axis=0), axis=-1).mean() * motion.fps**3)


def joint_jumps(motion: Motion) -> np.ndarray:
    """``(T - 1,)``: the largest distance (m) any joint moves between each two consecutive frames."""
    return np.linalg.norm(np.diff(motion.global_positions(), axis=0), axis=-1).max(axis=-1)


def largest_jump(motion: Motion) -> float:
    """The largest distance (m) any joint moves between two consecutive frames."""
    return float(joint_jumps(motion).max())


def bone_length_error(motion: Motion, reference: Skeleton) -> float:
    """Mean absolute difference (m) between the motion's bone lengths, frame by frame, and the
    reference skeleton's rest lengths.

    Bones are the links from each joint to its parent inside the pelvis's subtree; the link that
    carries the root trajectory (pelvis to its parent) is not a bone.
    """
    sk = motion.skeleton
    inside = set(feature_layout(sk).joints)
    bones = [j for j in range(sk.n_joints) if sk.parents[j] in inside]
    ref = np.array([reference.index(sk.names[j]) for j in bones])
    parents = [sk.parents[j] for j in bones]
    g = motion.global_positions()
    lengths = np.linalg.norm(g[:, bones] - g[:, parents], axis=-1)
    return float(np.abs(lengths - reference.bone_lengths()[ref]).mean())


def content_consistency(source: np.ndarray, output: np.ndarray) -> float:
    """Mean L2 distance between paired content embeddings (rows) of sources and outputs.

    This is MoST's content consistency (CC): 0 when the content judge sees the same motion.
    """
    source, output = np.atleast_2d(source), np.atleast_2d(output)
    if source.shape != output.shape:
        raise ValueError(f"paired embeddings must have one shape, got {source.shape} and {output.shape}")
    return float(np.linalg.norm(source - output, axis=-1).mean())
